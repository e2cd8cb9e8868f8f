"""Metrics stage: dynamic range, SNR and the paper's histogram coefficient.

* :mod:`bench_sim.metrics.dynamic_range` - eq. 15 (``20 lg(mu2/mu1)``) and the stage pairs that
  give a requested value.
* :mod:`bench_sim.metrics.histogram` - eq. 16-18: ``omega = var(histogram) / (M N)`` with a
  documented binning, and the evaluation of eq. 18.
* :mod:`bench_sim.metrics.snr` - SNR versus signal from image pairs (series or uniform patches).
* :mod:`bench_sim.metrics.emva1288` - EMVA 1288 R4 photon-transfer analysis (K, QE, saturation,
  ``mu_p.min``, measured dynamic range); its measurement and fit steps are in
  :mod:`bench_sim.metrics.photon_transfer`.
* :mod:`bench_sim.metrics.sfr` - ISO 12233:2017 slanted-edge SFR (e-SFR), MTF50, MTF at Nyquist
  (its ROI and invalid pixels: :mod:`bench_sim.metrics.sfr_roi`; the readings, MTF50P and
  sharpening: :mod:`bench_sim.metrics.sfr_readings`; many edges as a table:
  :mod:`bench_sim.metrics.sfr_table`); :mod:`bench_sim.metrics.edge_rois` finds the edges of a
  ``slanted_edges`` target, :mod:`bench_sim.metrics.edge_finder` every slanted edge of any image.
"""
