"""Measurements through the simulated chain: uniform fields, EMVA 1288 photon transfer (ptc),
the dynamic range of Gamma1, Gamma2 and Gamma_HDR, and the metrics of one pass."""
