"""The library's road from a recording to its buried targets, one stage per function.

    read_recording -> attach_trajectory (or fuse_recordings) -> apply_steps -> load_models -> detect -> add_depths
    -> reconstruct_recording -> write_result (or write_reconstruction_folder, the result folder as one whole)

Each stage takes and returns plain objects (a :class:`~gpr3d.core.survey.Survey`, a detection result dict, a reconstruction), so
a stage can be stopped at, looked into or replaced. The ``gpr3d`` commands are thin wrappers over these.
"""

from __future__ import annotations

import importlib

_WHERE = {
    "SURVEY_SUFFIXES": "recording", "place_traces": "recording", "apply_steps": "recording",
    "read_recording": "recording", "write_survey": "recording", "attach_trajectory": "recording",
    "load_models": "targets", "add_depths": "targets", "targets_from_file": "targets", "read_targets": "targets",
    "ReconstructionRun": "reconstruction", "reconstruct_recording": "reconstruction",
    "write_reconstruction_folder": "reconstruction", "write_result": "reconstruction", "FusedPoses": "poses",
    "fuse_recordings": "poses", "poses_at_traces": "poses", "write_rig_recordings": "poses",
    "RunConfig": "run", "run_pipeline": "run", "write_report": "report",
    "LiveConfig": "live", "open_source": "live", "run_live": "live",
    "replay_to_tcp": "replay", "replay_to_file": "replay", "read_sensors": "replay",
}

__all__ = sorted(_WHERE)


def __getattr__(name):  # the stages load what they need when first asked for (the CLI starts fast)
    if name in _WHERE:
        return getattr(importlib.import_module(f"gpr3d.pipeline.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'gpr3d.pipeline' has no attribute {name!r}")


def __dir__():
    return __all__
