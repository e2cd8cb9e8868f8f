"""Checks of ``bench-sim design``'s ``report.md`` statements against the candidate table they are about.

Each check parses sentences of the report (regular expressions on the text, not the report
writer's formatting code) and compares what they say with the table's columns and the judgement:
which candidate is recommended and why it ranks above the runner-up, what the configured pair fails
and what the recommendation gains or gives up against it (every "better"/"worse"/"equal"), where
the output word caps the DR and by how much (recomputed from the sensor model), the counts of
feasible, failing and front candidates, and every percentage ("0%" only for exactly 0).
:func:`check_report` returns the names of the checks that found their sentences and raises
``AssertionError`` naming the first false statement.
"""

from __future__ import annotations

import math
import re
from typing import Any

from bench_sim.measure.design_scores import word_config
from bench_sim.sensor.model import stage_clips_on_word, stage_dr_model_db, stage_saturation_photons
from bench_sim.workflows.design.objectives import OBJECTIVES

NUM = r"[-+]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?"


def _close(text: str, x: float) -> bool:
    """Whether a number as printed (its decimals or significant digits) states ``x``."""
    t = text.replace(",", "")
    if t.startswith("<"):
        return 0 < abs(x) < float(t[1:].strip().rstrip("%")) / (100 if t.endswith("%") else 1)
    if t.endswith("%"):
        v, scale = float(t.rstrip("%")), 100.0
        if v == 0 or abs(v) == 100:
            return scale * x == v
    else:
        v, scale = float(t.split()[0]), 1.0
    mant = t.rstrip("%").split()[0].lower().split("e")[0].lstrip("+-")
    if "e" in t.lower().split()[0] or (not t.endswith("%") and "." not in mant):
        digits = len(mant.replace(".", "").lstrip("0")) or 1
        return math.isclose(scale * x, v, rel_tol=0.5 * 10.0 ** (1 - digits) + 1e-12, abs_tol=1e-300)
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return abs(scale * x - v) <= 0.5 * 10.0**-decimals + 1e-9 * max(1.0, abs(v))


def _value(text: str, name: str, x: float) -> None:
    if text == "n/a":
        assert x is None or not math.isfinite(x), (name, text, x)
        return
    assert _close(text.replace(" dB", "").replace(" cycles/px", ""), x), (name, text, x)


def _row(c: dict[str, Any], stages: str, rule: str, beta: int, point: int | None = None) -> int:
    hits = [i for i in range(len(c["stages"])) if c["stages"][i] == stages and c["rule"][i] == rule
            and int(c["beta_bits"][i]) == beta and (point is None or int(c["point"][i]) == point)]
    assert len(hits) == 1, (stages, rule, beta, point, hits)
    return hits[0]


def check_recommended(text: str, c: dict[str, Any], j: Any) -> tuple[list[str], int | None]:
    m = re.search(r"\*\*Recommended design: stages (\S+), rule `(\w+)`, (\d+)-bit word\*\*, at point (\d+)"
                  r"[^\n]*\(candidate (\d+)\)", text)
    if m is None:
        assert "**No candidate meets the constraints**" in text and j.recommended is None
        return ["no_recommendation"], None
    i = int(m.group(5))
    assert i == j.recommended and int(c["rank"][i]) == 1
    assert _row(c, m.group(1), m.group(2), int(m.group(3)), int(m.group(4))) == i
    return ["recommended"], i


def check_runner_up(text: str, c: dict[str, Any], j: Any, rank: list[str]) -> list[str]:
    if "there is no runner-up" in text:
        assert j.runner_up is None and len(j.ranked) == 1
        return ["no_runner_up"]
    m = re.search(r"It ranks above the runner-up, (\S+) \(`(\w+)`, (\d+)-bit\) at point (\d+)[^:\n]*?"
                  r"(?:, on `(\w+)`(?:, after equal ([^:]+))?: (\S+%?(?: dB)?) against "
                  r"(\S+%?(?: dB)?)\.|: they tie)",
                  text)
    assert m is not None, "runner-up sentence"
    second = _row(c, m.group(1), m.group(2), int(m.group(3)), int(m.group(4)))
    best = j.recommended
    assert second == j.runner_up and int(c["rank"][second]) == 2
    keys = {r: (OBJECTIVES[r].key(float(c[r][best])), OBJECTIVES[r].key(float(c[r][second]))) for r in rank}
    if m.group(5) is None:
        assert all(a == b for a, b in keys.values())
        return ["runner_up_tie"]
    obj = m.group(5)
    first = next(r for r in rank if keys[r][0] != keys[r][1])
    assert obj == first and keys[obj][0] < keys[obj][1], (obj, keys)
    _value(m.group(7), obj, float(c[obj][best]))
    _value(m.group(8), obj, float(c[obj][second]))
    assert m.group(7) != m.group(8)
    return ["runner_up"]


def check_reference(text: str, c: dict[str, Any], j: Any, spec: Any) -> list[str]:
    best, ref = j.recommended, j.reference
    if f"is the configured pair {c['stages'][ref]}" in text:
        assert ref == best
        return ["reference_is_best"]
    m = re.search(r"Against the configured pair (\S+) \(`(\w+)`, (\d+)-bit\)[^:]*: "
                  r"(it fails the constraints, "
                  r"(.*?)\.|it meets the constraints and ranks (\d+) of (\d+)\.) ", text)
    assert m is not None and _row(c, m.group(1), m.group(2), int(m.group(3)), int(c["point"][best])) == ref
    failing = [k for k in spec.constraints if not k.met(float(c[k.objective][ref]))]
    if m.group(5) is not None:
        said = re.findall(r"`(\w+)` = (\S+%?(?: dB)?) \(needs ([^)]+)\)", m.group(5))
        assert [s[2] for s in said] == [k.text() for k in failing]
        for name, val, _ in said:
            _value(val, name, float(c[name][ref]))
    else:
        assert not failing and int(m.group(6)) == int(c["rank"][ref]) and int(m.group(7)) == len(j.ranked)
    d = float(c["dr_db"][best]) - float(c["dr_db"][ref])
    t = re.search(r"The recommended design (gains|gives up|has the same closed-form DR)"
                  r"(?: (< 0\.01|\S+) dB of "
                  r"closed-form DR)? \((\S+) dB against (\S+) dB\)\.", text)
    assert t is not None
    verb = {"gains": d > 0, "gives up": d < 0, "has the same closed-form DR": d == 0}
    assert verb[t.group(1)], (t.group(1), d)
    if t.group(2) is not None:
        assert _close(t.group(2), abs(d)) if not t.group(2).startswith("<") else 0 < abs(d) < 0.005 + 1e-12
    _value(t.group(3), "dr_db", float(c["dr_db"][best]))
    _value(t.group(4), "dr_db", float(c["dr_db"][ref]))
    return ["reference", *_check_versus(text, c, best, ref)]


def _check_versus(text: str, c: dict[str, Any], a: int, b: int) -> list[str]:
    m = re.search(r"On the other objectives: ([^\n]*)\.", text)
    if m is None:
        return []
    for part in m.group(1).split("; "):
        p = re.fullmatch(r"`(\w+)` (\S+(?: dB| cycles/px)?) against (\S+(?: dB| cycles/px)?)"
                         r"(?: \(([\w ]+)\))?",
                         part)
        assert p is not None, part
        name, va, vb = p.group(1), float(c[p.group(1)][a]), float(c[p.group(1)][b])
        _value(p.group(2), name, va)
        _value(p.group(3), name, vb)
        o = OBJECTIVES[name]
        if not (math.isfinite(va) and math.isfinite(vb)):
            assert p.group(4) == "not comparable"
            continue
        ka, kb = o.key(va), o.key(vb)
        assert p.group(4) == ("better" if ka < kb else "worse" if ka > kb else "equal")
        assert va == vb or p.group(2) != p.group(3), part  # two values never read alike
    return ["versus"]


def check_caps(text: str, c: dict[str, Any], spec: Any) -> list[str]:
    found = []
    for m in re.finditer(r"- The (\d+)-bit output word (caps|does not cap) the DR of the ([\w -]+?) (\S+) "
                         r"\(`(\w+)`, "
                         r"(\d+)-bit\)(?: at point (\d+))?([^\n]*)", text):
        beta, caps, stages, rule = int(m.group(1)), m.group(2) == "caps", m.group(4), m.group(5)
        candidates = [i for i in range(len(c["stages"])) if c["stages"][i] == stages and c["rule"][i] == rule
                      and int(c["beta_bits"][i]) == beta]
        i = candidates[0]
        cfg = word_config(spec.points[int(c["point"][i])].cfg, beta)
        s, t, mu = cfg.sensor, cfg.timing.t_int_s, int(c["mu1"][i])
        kw = {"subtract_black": cfg.dtdi.subtract_black, "pedestal_dn": cfg.dtdi.pedestal_dn}
        assert caps == stage_clips_on_word(s, mu, beta_bits=beta, **kw)
        rest = m.group(8)
        if caps:
            r = re.match(r" by (< 0\.01|\S+) dB: its stage (\d+) clips on the word at (\S+) photons per "
                         r"pixel per frame, below its pixel's clip at (\S+); (?:a word of (\d+) bits or more "
                         r"would not cap it|no word up to 32 bits would lift it)\.", rest)
            assert r is not None, rest
            cap = float(c["dr_cap_db"][i])
            assert cap > 0 and (_close(r.group(1), cap) if r.group(1)[0] != "<" else cap < 0.005 + 1e-12)
            assert int(r.group(2)) == mu
            assert _close(r.group(3), stage_saturation_photons(s, t, mu, beta_bits=beta, **kw))
            assert _close(r.group(4), stage_saturation_photons(s, t, mu, beta_bits=None, **kw))
            enough = r.group(5)
            if enough is not None:
                b = int(enough)
                assert not stage_clips_on_word(s, mu, beta_bits=b, **kw)
                assert stage_clips_on_word(s, mu, beta_bits=b - 1, **kw)
        else:
            assert float(c["dr_cap_db"][i]) == 0.0
        single = stage_dr_model_db(cfg, 1)
        below = re.match(r"\n  Its DR \((\S+) dB\) is below that of a single read[^(]*\(stage 1: (\S+) dB\)",
                         text[m.end():])
        assert (below is not None) == (float(c["dr_db"][i]) < single)
        found.append("caps" if caps else "no_cap")
    return found


def check_counts(text: str, c: dict[str, Any], j: Any, spec: Any, chain: dict[int, Any]) -> list[str]:
    n = len(c["stages"])
    if spec.constraints:
        m = re.search(r"(\d+) of (\d+) candidates meet the constraints", text)
        assert m is not None and int(m.group(1)) == int(j.feasible.sum()) and int(m.group(2)) == n
        for k in spec.constraints:
            f = re.search(re.escape(f"- {k.text()}: ") + r"(\d+) candidates fail it\.", text)
            assert f is not None and int(f.group(1)) == sum(1 for v in c[k.objective] if not k.met(float(v)))
    else:
        assert f"No constraints: all {n} candidates are feasible." in text
    m = re.search(r"(\d+) candidates are on the Pareto front", text)
    assert m is not None and int(m.group(1)) == int(j.front.sum())
    m = re.search(r"measured for [^:]+: (\d+) pairs", text)
    assert m is not None and int(m.group(1)) == sum(1 for r in chain.values() if r.get("status") == "ok")
    return ["counts"]


def check_report(text: str, c: dict[str, Any], j: Any, spec: Any, chain: dict[int, Any]) -> list[str]:
    """Every checked statement of ``text`` (module docstring); returns the checks that found theirs."""
    found, best = check_recommended(text, c, j)
    found += check_counts(text, c, j, spec, chain)
    if best is not None:
        found += check_runner_up(text, c, j, list(spec.rank))
        found += check_reference(text, c, j, spec)
        found += check_caps(text, c, spec)
    # no percentage reads 0 or 100 unless exact
    for tok in re.findall(r"(?<![\w.])([-+]?\d+(?:\.\d+)?%)", text):
        assert tok.lstrip("+-") not in ("0.0%", "100.0%"), tok
    return found
