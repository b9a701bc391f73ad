"""Paper reproductions and studies (``python -m pipeline study <name>``, registry
:mod:`pipeline.papers.registry`); no stage imports them.

Calibration studies (the calibration stage on simulated arms, scored on held-out poses):

- :mod:`~pipeline.papers.calib_000` (``calib-000``): paper 000's TCP-covariance design on the KUKA
  arms; its cell :mod:`~pipeline.papers.calib_000_scene`, tables
  :mod:`~pipeline.papers.calib_000_report`, elasticity outlook :mod:`~pipeline.papers.calib_000_elastic`;
- :mod:`~pipeline.papers.calib_002` (``calib-002``): paper 002's identifiable parameter sets;
- :mod:`~pipeline.papers.calib_003` (``calib-003``): paper 003's indices O1..Oc with DETMAX and BSAA
  (:mod:`~pipeline.papers.calib_003_search`);
- :mod:`~pipeline.papers.calib_003_sizes` (``calib-003-sizes``): the same searches for 30-200 of the
  583 poses on the literal (model-consistent) hidden robot;
- :mod:`~pipeline.papers.calib_004` (``calib-004``): paper 004 §3.4 with the optical 6-D tracker
  (:mod:`~pipeline.papers.calib_004_optical`), its "linear scan" baselines
  (:mod:`~pipeline.papers.calib_004_scans`) and the laser-tracker variant
  (:mod:`~pipeline.papers.calib_004_laser`);
- :mod:`~pipeline.papers.calib_design` (``calib-design``): which index x selector gives the most
  accurate TCP in the working region;
- :mod:`~pipeline.papers.calib_six_d`: simulated 6-D motion-capture records calibrated through the
  stage (``benchmarks/bench_six_d.py``);
- :mod:`~pipeline.papers.calib_common`: parallel runs over seeds, ``result.json``.

Whole-chain reproductions (every stage):

- :mod:`~pipeline.papers.chain_004` (``paper-004``): paper 004 §2.3.3, §4, §5 (control,
  identification, CP/PtP) on the RX130L; its rows beside the paper in
  :mod:`~pipeline.papers.chain_004_rows`; Fig. 2(b) against the hidden robot's joint stiffness
  (``paper-004 --compliance-scales``) in :mod:`~pipeline.papers.chain_004_stiffness`.
"""
