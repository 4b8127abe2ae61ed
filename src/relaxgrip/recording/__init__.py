"""Record runs of the loop to MCAP, replay them offline, turn them into datasets.

The core imports without the ``mcap`` package; writing or reading a recording
needs it (``pip install 'relaxgrip[record]'``) and says so when it is missing.

* :class:`McapRecorder` (``run_loop(..., recorder=...)``, ``relaxgrip hold --record``)
* :func:`iter_periods`, :func:`recover` (``relaxgrip recover``)
* :func:`replay` (``relaxgrip replay``)
* :func:`dataset_from_recordings` (``relaxgrip dataset from-recordings``)
"""

from __future__ import annotations

from relaxgrip.recording.dataset import dataset_from_recordings
from relaxgrip.recording.reader import iter_messages, iter_periods, read_session, recover
from relaxgrip.recording.recorder import McapRecorder, require_mcap
from relaxgrip.recording.replay import ReplayResult, replay
from relaxgrip.recording.schemas import CHANNELS, RECORDING_FORMAT

__all__ = [
    "CHANNELS",
    "RECORDING_FORMAT",
    "McapRecorder",
    "ReplayResult",
    "dataset_from_recordings",
    "iter_messages",
    "iter_periods",
    "read_session",
    "recover",
    "replay",
    "require_mcap",
]
