"""Fig. 4 of ``reproduce``: each inset caption states what was measured inside the box it captions
(:mod:`bench_sim.workflows.reproduce.fig4_captions`), and the figure has no empty bands for a
``--quick`` image (wider than tall) nor for the full one."""

from __future__ import annotations

import re

import matplotlib
import numpy as np
import pytest

from bench_sim.config import load_config, with_overrides
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.measure.pass_metrics import patch_slices
from bench_sim.pipeline import run_pass
from bench_sim.sensor.model import stage_offset_dn
from bench_sim.workflows.reproduce.fig4_captions import inset_captions, inset_facts, pass_inset_captions
from bench_sim.workflows.reproduce.figures import fig4_layout

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

TOP = 4095


def _scene(rng: np.random.Generator):
    """A 120 x 200 image: a 90 % step wholly clipped in Gamma2 outside the bright box, a bright
    box (the bars) 73 % clipped, two dark steps inside the dark box and a darker one outside."""
    shape = (120, 200)
    g2 = rng.uniform(0, 3000, shape)
    g2[0:20, 0:40] = TOP  # the 90 % step: 100 % at the top, not in the bright box
    bright = (40, 80, 0, 50)
    box = g2[40:80, 0:50]
    box[rng.random(box.shape) < 0.73] = TOP
    hdr = rng.normal(500, 50, shape)
    g1 = hdr / 8
    patches = {"wedge_right_14": (slice(90, 100), slice(120, 140)),
               "wedge_right_15": (slice(100, 110), slice(120, 140)),
               "wedge_right_16": (slice(100, 110), slice(170, 190))}  # outside the dark box
    hdr[100:110, 120:140] = rng.normal(20, 5, (10, 20))  # 2 % step, inside: SNR 4
    g1[100:110, 120:140] = rng.normal(2.5, 1.25, (10, 20))  # SNR 2 in Gamma1
    hdr[100:110, 170:190] = rng.normal(5, 5, (10, 20))  # darker, but outside the box
    dark = (85, 115, 110, 150)
    at_top1 = np.zeros(shape, bool)
    at_top1[50:55, 0:10] = True
    from_g2 = np.ones(shape, bool)
    from_g2[40:60, 0:50] = False  # half the bright box from Gamma1
    refl = {"wedge_right_14": 0.03, "wedge_right_15": 0.02, "wedge_right_16": 0.01}
    return g1, hdr, g2 >= TOP, at_top1, from_g2, dark, bright, patches, refl


def _pct(caption: str, after: str) -> float:
    m = re.search(rf"{re.escape(after)}\s*([\d.]+)%", caption)
    assert m, caption
    return float(m[1]) / 100


def test_each_caption_states_what_was_measured_in_its_own_box():
    g1, hdr, g2_top, hdr_top, from_g2, dark, bright, patches, refl = _scene(np.random.default_rng(5))
    captions = inset_captions(inset_facts(g1, hdr, g2_top, hdr_top, from_g2, dark, bright, patches, refl))
    b = (slice(bright[0], bright[1]), slice(bright[2], bright[3]))
    # the bright Gamma2 caption: the bar box's fraction (~73 %), not the 90 % step's 100 %
    clipped = float(np.mean(g2_top[b]))
    assert 0.6 < clipped < 0.85
    assert _pct(captions[2], "$\\Gamma_2$:") == pytest.approx(clipped, abs=0.0005)
    assert _pct(captions[3], "HDR") == pytest.approx(float(np.mean(hdr_top[b])), abs=0.0005)
    assert _pct(captions[3], "top,") == pytest.approx(float(np.mean(from_g2[b] & g2_top[b])), abs=0.0005)
    # the dark captions: the darkest step inside the dark box (2 %), not the darker one outside
    sl = patches["wedge_right_15"]
    for caption, img in ((captions[0], g1), (captions[1], hdr)):
        assert "2% step" in caption and "spatial SNR" in caption
        found = re.search(r"SNR ([\d.]+)$", caption)
        assert found, caption
        snr = float(found[1])
        assert snr == pytest.approx(img[sl].mean() / img[sl].std(), abs=0.05)


def test_without_a_step_in_the_dark_box_the_caption_says_it_measured_the_box():
    g1, hdr, g2_top, hdr_top, from_g2, dark, bright, patches, refl = _scene(np.random.default_rng(6))
    facts = inset_facts(g1, hdr, g2_top, hdr_top, from_g2, (0, 30, 150, 200), bright, patches, refl)
    assert facts.dark_region == "box"
    assert "over the box" in inset_captions(facts)[0]


@pytest.mark.parametrize("shape", [(256, 512), (1024, 1024), (96, 192)], ids=["quick", "full", "tiny"])
def test_fig4_panels_fill_their_slots(shape):
    """No empty bands: each big panel's image fills its slot (the slot is as tall as the image at
    the slot's width), for the --quick image as for the full one."""
    h, w = shape
    boxes = [(h // 2, h, w // 2, w // 2 + w // 8), (0, h // 4, 0, w // 2)]
    size, rects = fig4_layout(shape, boxes)
    images = [shape, shape, *((b[1] - b[0], b[3] - b[2]) for b in (boxes[0], boxes[0], boxes[1], boxes[1]))]
    fig = plt.figure(figsize=size, dpi=50)
    try:
        for rect, img in zip(rects, images, strict=True):
            ax = fig.add_axes(rect)
            ax.imshow(np.zeros(img, np.float32))
            ax.apply_aspect()
            got = ax.get_position()
            assert got.height == pytest.approx(rect[3], rel=0.02)
            assert got.width == pytest.approx(rect[2], rel=0.02)
            assert 0 <= rect[1] and rect[1] + rect[3] <= 1
    finally:
        plt.close(fig)


def test_captions_of_a_real_pass_are_the_numbers_of_their_boxes():
    """On a small real pass: the bright caption is the bar box's fraction at the word's top, read
    back from the stage word; a box over the brightest wedge step (100 % clipped) gives another."""
    cfg = with_overrides(load_config(), {
        "lines": 96, "sensor": {"columns": 192}, "target": {"panel_lines": 96, "panel_columns": 192},
        "render": {"spp": 2},
    })
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    sim = run_pass(cfg, [mu1, mu2], 3, truth=False)
    off1, off2 = (stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    fused = fuse_dtdi_hdr_eq11(sim.stage_dn[mu1], sim.stage_dn[mu2], mu1=mu1, mu2=mu2, beta=beta,
                               pedestal_dn=(off1, off2))
    panel, geom = sim.setup.grid.panel, sim.setup.geom
    wedge = {k: v for k, v in patch_slices(panel, geom, cfg, cfg.lines).items() if k.startswith("wedge_")}
    step = wedge["wedge_left_00"]  # the 90 % step under the spot
    h, w = sim.stage_dn[mu2].shape
    got = []
    step_box = (step[0].start, step[0].stop, step[1].start, step[1].stop)
    for bright in ((0, h // 3, w // 3, 2 * w // 3), step_box):
        captions = pass_inset_captions(cfg, sim.stage_dn, fused, ((h // 2, h, 0, w), bright), panel,
                                       geom)
        got.append(captions[2])
        at_top = sim.stage_dn[mu2][bright[0]:bright[1], bright[2]:bright[3]] >= 2**beta - 1
        assert _pct(captions[2], "$\\Gamma_2$:") == pytest.approx(float(at_top.mean()), abs=0.0005)
    assert got[0] != got[1] and "100% at the word's top" in got[1]  # each box its own number
