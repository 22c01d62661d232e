"""fdi-sim: an aircraft fault detection and isolation testbed on JSBSim.

Map of the package (data-flow order):

- ``fdi_sim.aircraft``   JSBSim adapter: load, start engines, trim, property map (the only jsbsim import)
- ``fdi_sim.scenario``   TOML scenario files -> frozen, validated objects
- ``fdi_sim.pilot``      autopilot holds and maneuvers (doublets, 3-2-1-1, steps, turns)
- ``fdi_sim.faults``     actuator, sensor and icing faults with time profiles
- ``fdi_sim.sensors``    sensor suite models (noise, bias, sample rate, quantization)
- ``fdi_sim.linear``     linear models, trim grid, linearization, model schedule
- ``fdi_sim.detectors``  residual generators (parity, robust parity, stochastic parity, PCA, observers)
- ``fdi_sim.decision``   thresholds, tests, isolation, failure log
- ``fdi_sim.sim``        the loop that wires the stages together
- ``fdi_sim.flightlog``  MCAP writing, reading and repair
- ``fdi_sim.study``      Monte Carlo campaigns
- ``fdi_sim.review``     figures and reports from logs
- ``fdi_sim.papers``     seed-paper reproductions and flight studies (they may fly simulations; nothing imports them)
"""
from __future__ import annotations

__version__ = "0.1.0"
