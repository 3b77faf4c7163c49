"""Raw BioTac trials: the signals as recorded, validated, read from and written to HDF5.

A trial is one exploration of an object by a gripper with one or more BioTac fingers (two
on the PR2). Per finger it holds the channels of the BioTac ROS driver, named as there and
in the HDF5 files of ``../shared/data/biotac_pilot`` (T frames, any T >= 2):

=============  ========  ==========================================================
channel        shape     meaning
=============  ========  ==========================================================
``pdc``        (T,)      DC pressure
``tdc``        (T,)      DC temperature
``tac``        (T,)      AC temperature (heat flow)
``pac``        (T, 22)   AC pressure (vibration), 22 sub-samples per frame
``electrodes`` (T, 19)   impedance of the 19 electrodes
=============  ========  ==========================================================

The fingers of one trial are recorded together: they have the same number of frames.
A trial may carry its exploration phases as ``[start, end)`` frame ranges shared by its
fingers, and the frames' timestamps; without phases they are found in each finger's
``pdc`` by a ``PhaseRule`` (see its docstring and docs/DATASETS.md).

Every problem with a trial raises ``RawTrialError``, whose message and attributes name the
trial index (or file and group), the finger and the channel.

The HDF5 layout (read by ``read_biotac_h5``, written by ``write_biotac_h5``): one group per
trial holding ``finger_0`` … ``finger_<F-1>`` groups with one dataset per channel, and
optionally ``timestamps`` (T,) and ``phases`` (P, 2) next to them. The pilot's files are
PyTables files of that layout without ``phases``; other members of a trial group (other
sensors a recording may carry) are ignored.

The pieces live in modules of their own, and every name is importable from here as before:
``app.data.biotac_errors`` (``RawTrialError``), ``app.data.biotac_trial`` (the channels,
``FingerSignals``, ``RawTrial``, ``parse_trial``), ``app.data.biotac_phases``
(``PhaseRule``), ``app.data.biotac_h5`` (reading and writing HDF5) and
``app.data.biotac_dataset`` (``BioTacDataset`` and the ``biotac:`` folder).
"""

from app.data.biotac_dataset import H5_SUFFIXES as H5_SUFFIXES
from app.data.biotac_dataset import OBJECTS_FILE as OBJECTS_FILE
from app.data.biotac_dataset import (
    BioTacDataset,
    load_biotac,
    pressure_from_group,
    write_biotac_folder,
)
from app.data.biotac_errors import RawTrialError
from app.data.biotac_h5 import read_biotac_h5, write_biotac_h5
from app.data.biotac_phases import PhaseRule
from app.data.biotac_trial import (
    CHANNELS,
    FingerSignals,
    RawTrial,
    parse_trial,
    parse_trials,
)
from app.data.biotac_trial import MIN_FRAMES as MIN_FRAMES
from app.data.biotac_trial import N_ELECTRODES as N_ELECTRODES
from app.data.biotac_trial import PAC_SUBSAMPLES as PAC_SUBSAMPLES

__all__ = [
    "CHANNELS",
    "BioTacDataset",
    "FingerSignals",
    "PhaseRule",
    "RawTrial",
    "RawTrialError",
    "load_biotac",
    "parse_trial",
    "parse_trials",
    "pressure_from_group",
    "read_biotac_h5",
    "write_biotac_folder",
    "write_biotac_h5",
]
