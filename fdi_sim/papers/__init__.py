"""Reproductions of the seed documents' examples and one-off flight studies.

These modules may fly simulations; nothing in the library imports them (``tests/test_layering.py``).

- :mod:`fdi_sim.papers.hagenblad_f16`       Hagenblad et al. F-16 parity and PCA examples (eq. 23-27)
- :mod:`fdi_sim.papers.sidar_examples`      Sidar 1982 sec. VI adaptive-observer examples (figs. 6-9)
- :mod:`fdi_sim.papers.twin_otter_interim`  hand-built INTERIM Twin Otter longitudinal model
- :mod:`fdi_sim.papers.dhc6_icing_flights`  DHC-6 icing study: seeded JSBSim flights and their models
- :mod:`fdi_sim.papers.dhc6_icing_study`    DHC-6 icing study: robust-parity designs and statistics
"""
from __future__ import annotations
