"""Compiled streams of the seed papers' detectors: which runtime engine runs which registered detector.

:func:`compiled_stream` maps a designed detector to its block kernel
(:class:`~fdi_sim.detectors.stream.StreamingDetector`):

==================================================  ===============================================
designed detector (registry ids)                    stream
==================================================  ===============================================
``WindowParityDetector`` (parity-v1,                :class:`~fdi_sim.detectors.window_stream.WindowParityStream`
parity-robust-v1, parity-stochastic-v1, pca-v1)     (Lou, Willsky & Verghese 1986; Hagenblad et al.)
``BeardJonesFilter`` / ``BeardJonesBank``           :class:`~fdi_sim.detectors.observer_stream.ObserverStream`
(beard-jones-v1), ``LmiDetectionFilter``            (Miller & Ribbens, US 6,643,569 B2, App. A, B)
(lmi-detection-v1)
``KalmanInnovationDetector`` (kalman-nis-v1)        :class:`~fdi_sim.detectors.observer_stream.ObserverStream`
                                                    (Sidar 1982, NIS / bias / whiteness)
==================================================  ===============================================

Any other detector (the adaptive observer, the time-varying Kalman filter, the multiple-model
bank, a plugin) gets None: the bank runs it through its ``step``
(:class:`~fdi_sim.detectors.step_stream.StepStream`).
"""
from __future__ import annotations

from typing import Any, Sequence

from fdi_sim.detectors.observer_stream import ObserverStream, observer_stream
from fdi_sim.detectors.stream import StreamingDetector
from fdi_sim.detectors.window_stream import WindowParityStream, window_parity_stream

__all__ = ["ObserverStream", "WindowParityStream", "compiled_stream"]


def compiled_stream(det: Any, model: Any, command_names: Sequence[str], id: str | None = None) -> StreamingDetector | None:
    """The compiled streaming form of a designed detector, or None if it has none.

    Parameters
    ----------
    det : object
        A designed detector (a registry factory's result).
    model : LinearModel
        The model it was designed from (signal names, the trim non-command inputs are held at).
    command_names : sequence of str
        The commands the loop logs; the stream's ``input_names`` are the model inputs among them.
    id : str, optional
        The member id (default ``det.id``).

    Returns
    -------
    StreamingDetector or None
        :class:`WindowParityStream` or :class:`ObserverStream`; None for detector types without a
        kernel here (adaptive observer, time-varying Kalman, multiple-model bank, plugins).
    """
    for make in (window_parity_stream, observer_stream):
        stream = make(det, model, command_names, id)
        if stream is not None:
            return stream
    return None
