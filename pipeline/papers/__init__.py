"""Paper reproductions that run the whole pipeline (``python -m pipeline study paper-...``).

- :mod:`pipeline.papers.paper_004`: paper 004 §2.3.3, §4, §5 (control, identification, CP/PtP)
  on the RX130L; its rows beside the paper in :mod:`pipeline.papers.paper_004_rows`.
"""
