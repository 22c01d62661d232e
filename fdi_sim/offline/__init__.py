"""Detection over a flight log, after the flight (``fdi-sim detect``): registered detectors run on
the logged samples, or the log's own bank replayed bit for bit.

- :mod:`fdi_sim.offline.detect`: :func:`~fdi_sim.offline.detect.detect_log`,
  :func:`~fdi_sim.offline.detect.replay_bank`.
"""
