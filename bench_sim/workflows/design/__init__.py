"""``bench-sim design``: which stages, rule, word and timing to use for a camera and a scene."""
