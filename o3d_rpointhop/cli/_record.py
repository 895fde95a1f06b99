"""What an output records about the run that made it, and the config a record gives
back (``o3d-rpointhop config --from``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ._common import CommandError
from ._config import default_config, merge

__all__ = ["config_of_record", "run_record", "write_record"]


def run_record(command: str, config: dict[str, dict], descriptor: Any) -> dict[str, Any]:
    """What an output records about the run that made it: the library's version and
    commit, Open3D's, numpy's and Python's, the command, the descriptor (class, model
    name, content hash, parameters) and the whole config, which
    ``o3d-rpointhop config --from`` turns back into a file that repeats the run."""
    from .._utils.provenance import json_safe, library_facts
    from ..descriptors import descriptor_identity
    from ..registration.defaults import default_descriptor

    return {
        **library_facts(),
        "command": command,
        "descriptor": descriptor_identity(
            default_descriptor() if descriptor is None else descriptor
        ),
        "config": json_safe(config),
    }


def write_record(output: str, record: dict[str, Any]) -> str:
    """``record`` as JSON beside a file whose format holds none (``<output>.json``,
    ``{"provenance": record}``, which ``config --from`` reads); returns its path."""
    import json

    path = f"{output}.json"
    Path(path).write_text(json.dumps({"output": str(output), "provenance": record}, indent=2))
    return path


def config_of_record(path: str) -> dict[str, dict[str, Any]]:
    """The config a JSON output's ``"provenance"`` recorded (CommandError for a file
    without one)."""
    import json

    from ..io import read_provenance

    if not Path(path).is_file():
        raise CommandError(f"{path}: no such file")
    if Path(path).suffix.lower() in (".las", ".laz", ".ply"):  # a cloud a command wrote
        data = {"provenance": read_provenance(path)}
    else:
        try:
            data = json.loads(Path(path).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise CommandError(f"{path}: not a JSON file ({exc})") from None
    record = data.get("provenance") if isinstance(data, dict) else None
    if not isinstance(record, dict) or not isinstance(record.get("config"), dict):
        raise CommandError(
            f"{path}: records no run (no 'provenance' with a 'config'); written by "
            "register, reconstruct, describe or fit?"
        )
    config = record["config"]
    defaults = default_config()
    out: dict[str, dict[str, Any]] = {}
    for section, values in config.items():  # checked as a --config file would be
        for key, value in values.items():
            merge(out, defaults, section, key, value, path)
    return out
