"""``tactile-zsl dataset``: check a dataset spec, or export a dataset as a ``folder:`` one."""

from __future__ import annotations

import argparse
import json
from collections import Counter
from typing import Any

SPEC_HELP = (
    "dataset spec: 'simulated', 'simulated:N', 'phac2[:PATH]', 'biotac:DIR' (raw BioTac "
    "trials, one HDF5 file per object) or 'folder:DIR' (objects.csv, samples.npy, "
    "samples.csv); formats in docs/DATASETS.md"
)
FEATURIZED = (
    "A raw BioTac dataset is featurized into tactile images, one per finger of each trial, "
    "by a TactileImageFeaturizer with its default parameters (three phases found in pdc, "
    "30 time samples, 4 electrode principal components, resting levels subtracted) whose "
    "PCA and row normalisation are fitted on all of the dataset's trials."
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dataset",
        help="check a dataset, or export one as a folder: dataset",
        description="'check' loads a dataset spec, validates every file, trial and sample, and "
        "prints a JSON summary (objects, trials, samples, input shape or raw channels, "
        "attributes); a bad dataset exits with status 2 and a message that names the file, "
        "the row or group and the field. 'export' writes any dataset as a folder: dataset "
        "that loads back identical. " + FEATURIZED,
    )
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    check = actions.add_parser(
        "check",
        help="validate a dataset and print a summary",
        description="Validate a dataset and print a JSON summary. For biotac:DIR every finger "
        "of every trial must show its exploration phases (docs/DATASETS.md).",
    )
    check.add_argument("spec", help=SPEC_HELP)
    check.add_argument("--seed", type=int, default=0, help="seed of simulated data (default 0)")
    check.set_defaults(handler=run_check)
    export = actions.add_parser(
        "export",
        help="write a dataset as a folder: dataset",
        description="Write a dataset as objects.csv, samples.npy and samples.csv in --out, "
        "which 'folder:OUT' loads back with the same samples, labels, trials, attributes, "
        "names and object ids. " + FEATURIZED,
    )
    export.add_argument("--dataset", required=True, help=SPEC_HELP)
    export.add_argument("--out", required=True, help="folder to write (created if absent)")
    export.add_argument("--seed", type=int, default=0, help="seed of simulated data (default 0)")
    export.add_argument(
        "--overwrite", action="store_true", help="replace the files of a dataset already in --out"
    )
    export.set_defaults(handler=run_export)
    bag = actions.add_parser(
        "bag",
        help="write ROS 2 bags of the bridge's topics as a biotac: or folder: dataset",
        description="Read ROS 2 bags (mcap or sqlite3, as 'ros2 bag record' writes them) of "
        "the tactile_zsl bridge's topics, each the recording of one object, and write them as "
        "a dataset in --out: raw frames with procedure marks (topics ending in "
        "tactile_zsl/frames and tactile_zsl/procedure) as a biotac: folder, one trial per "
        "procedure...end, assembled as the bridge assembles them; samples (tactile_zsl/"
        "samples) as a folder: dataset, each message a trial. The dataset is loaded back and "
        "summarised as 'check' does (docs/ROS2.md).",
    )
    bag.add_argument(
        "recordings", nargs="+", metavar="OBJECT=BAG", help="a bag and the object it recorded"
    )
    bag.add_argument("--out", required=True, help="folder to write (created if absent)")
    bag.add_argument(
        "--procedures",
        help="the procedures of a trial, in order, as the marks name them (tap,hold,squeeze); "
        "of samples, their layout (default: the one the recorded /diagnostics name)",
    )
    bag.add_argument("--overwrite", action="store_true", help="replace files already in --out")
    bag.set_defaults(handler=run_bag)


def _attributes(names: tuple[str, ...], values: Any) -> dict[str, Any]:
    import numpy as np

    known = ~np.isnan(values)
    return {
        "count": len(names),
        "names": list(names),
        "binary": bool(len(names) and np.isin(values, (0.0, 1.0)).all()),
        "graded_values": int((known & ~np.isin(values, (0.0, 1.0))).sum()),
        "not_known_values": int((~known).sum()),
    }


def summarize(data: Any) -> dict[str, Any]:
    """A JSON-ready summary of a TactileDataset or a BioTacDataset (whose phases it checks)."""
    import numpy as np

    from app.data.biotac import CHANNELS, BioTacDataset

    if isinstance(data, BioTacDataset):
        from app.framework.tactile_image import TactileImageFeaturizer

        featurizer = TactileImageFeaturizer().fit(data.trials)  # finds every finger's phases
        fingers = Counter(t.n_fingers for t in data.trials)
        frames = [t.n_frames for t in data.trials]
        pressures = Counter(
            "unknown" if np.isnan(p) else f"{p:g}" for p in data.grip_pressure.tolist()
        )
        return {
            "name": data.name,
            "form": "raw BioTac trials",
            "objects": data.n_classes,
            "object_names": list(data.class_names),
            "trials": len(data),
            "trials_per_object": dict(Counter(data.class_names[i] for i in data.labels)),
            "fingers_per_trial": {str(k): v for k, v in sorted(fingers.items())},
            "frames": {"min": min(frames), "max": max(frames)},
            "raw_channels": {c: "(T,)" if w is None else f"(T, {w})" for c, w in CHANNELS.items()},
            "grip_pressure": dict(sorted(pressures.items())),
            "phases": f"{len(featurizer.phase_names)} per finger "
            f"({', '.join(featurizer.phase_names)}), found in every finger",
            "image_shape": list(featurizer.image_shape),
            "samples": int(sum(fingers[k] * k for k in fingers)),
            "attributes": _attributes(data.attribute_names, data.attribute_values),
        }
    per_object = np.bincount(data.labels, minlength=data.n_classes)
    return {
        "name": data.name,
        "form": "samples",
        "objects": data.n_classes,
        "object_names": list(data.class_names),
        "trials": int(len(np.unique(data.trials))),
        "samples": len(data),
        "samples_per_object": {"min": int(per_object.min()), "max": int(per_object.max())},
        "input_shape": list(data.input_shape),
        "procedures": list(data.procedures),
        "attributes": _attributes(data.attribute_names, data.attribute_values),
    }


def run_check(args: argparse.Namespace) -> int:
    from app.data.sources import open_dataset

    print(json.dumps(summarize(open_dataset(args.spec, seed=args.seed)), indent=2))
    return 0


def run_export(args: argparse.Namespace) -> int:
    from app.data.folder import write_folder
    from app.data.sources import load_dataset

    dataset = load_dataset(args.dataset, seed=args.seed)
    out = write_folder(dataset, args.out, overwrite=args.overwrite)
    summary = summarize(dataset)
    print(json.dumps({"out": str(out), "spec": f"folder:{out}", **summary}, indent=2))
    return 0


def run_bag(args: argparse.Namespace) -> int:
    from pathlib import Path

    from app.data import rosbag
    from app.data.folder import write_folder
    from app.data.sources import open_dataset

    recordings = [rosbag.Recording.parse(r) for r in args.recordings]
    procedures = None
    if args.procedures is not None:
        procedures = tuple(p.strip() for p in args.procedures.split(",") if p.strip())
        if not procedures:
            raise ValueError("--procedures names no procedure")
    out = Path(args.out)
    topics, _ = rosbag.read_messages(recordings[0].path, ())
    if rosbag.find_topic(topics, rosbag.FRAMES) is not None:
        marks = procedures or rosbag.DEFAULT_PROCEDURES
        rosbag.write_biotac_from_bags(recordings, out, marks, args.overwrite)
        spec = f"biotac:{out}"
    else:
        dataset = rosbag.samples_from_bags(recordings, procedures)
        write_folder(dataset, out, overwrite=args.overwrite)
        spec = f"folder:{out}"
    print(json.dumps({"out": str(out), "spec": spec, **summarize(open_dataset(spec))}, indent=2))
    return 0
