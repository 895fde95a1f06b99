"""Configuration files for the command line: one TOML section per step and one for the
settings, keys are the library's parameter names (as KISS-ICP's config is), with
``--set section.parameter=value`` for one-off changes and ``o3d-rpointhop config`` to
print the defaults as a file to start from."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

from ._common import CommandError, UsageError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["default_config", "load_config", "registration_options", "to_toml"]

#: ``[register]``: the arguments of ``register()`` the command line also has as flags.
REGISTER_KEYS = {
    "global_method": "auto",
    "refine": "point_to_plane",
    "voxel_size": "auto",
    "n_global_points": "auto",
    "seed": 0,
    "symmetry_check": False,
}
# Step parameters a file cannot give (objects, not values).
_OBJECT_PARAMETERS = {"descriptor", "refine"}


def _steps() -> dict[str, type]:
    from ..registration.pipeline import GLOBAL_METHODS, REFINE_METHODS

    return {**GLOBAL_METHODS, **REFINE_METHODS}


def _settings_defaults() -> dict[str, Any]:
    from ..registration import RegistrationSettings

    plain = RegistrationSettings()
    return {
        f.name: getattr(plain, f.name)
        for f in dataclasses.fields(RegistrationSettings)
        if f.name != "voxel_size"
    }


def default_config() -> dict[str, dict[str, Any]]:
    """Every section with its defaults (``None``: derived from the settings)."""
    config: dict[str, dict[str, Any]] = {"register": dict(REGISTER_KEYS)}
    for name, cls in _steps().items():
        params = cls().get_params(deep=False)
        config[name] = {k: v for k, v in params.items() if k not in _OBJECT_PARAMETERS}
    config["settings"] = _settings_defaults()
    return config


def _merge(config: dict, defaults: dict, section: str, key: str, value: Any, where: str) -> None:
    if section not in defaults:
        raise UsageError(f"{where}: unknown section [{section}]; sections: {', '.join(defaults)}")
    if key not in defaults[section]:
        raise UsageError(
            f"{where}: [{section}] has no parameter {key!r}; it has: "
            f"{', '.join(sorted(defaults[section]))}"
        )
    if isinstance(defaults[section][key], tuple) and isinstance(value, list):
        value = tuple(value)
    config.setdefault(section, {})[key] = value


def load_config(path: str | None, sets: list[str] | None = None) -> dict[str, dict]:
    """The values a config file and ``--set`` items give, checked against the known
    sections and parameters (values are checked by the steps themselves)."""
    config: dict[str, dict] = {}
    defaults = default_config()
    if path:
        try:
            data = tomllib.loads(Path(path).read_text())
        except FileNotFoundError:
            raise CommandError(f"{path}: no such config file") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise CommandError(f"{path}: not a TOML file ({exc})") from None
        for section, values in data.items():
            if not isinstance(values, dict):
                raise CommandError(f"{path}: {section!r} must be a [section], not a value")
            for key, value in values.items():
                _merge(config, defaults, section, key, value, path)
    for item in sets or []:
        name, sep, text = item.partition("=")
        section, dot, key = name.strip().partition(".")
        if not (sep and dot and key):
            raise UsageError(f"--set {item!r}: expected section.parameter=value")
        try:  # a TOML value (numbers, true/false, quoted strings, arrays) or a bare word
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        _merge(config, defaults, section, key.strip(), value, "--set")
    return config


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(value)


def to_toml(config: dict[str, dict[str, Any]]) -> str:
    """``config`` as a TOML file; parameters whose default is ``None`` (derived from the
    settings' resolution) are written commented out."""
    lines = [
        "# o3d-rpointhop configuration: one section per step, keys are the library's",
        "# parameter names (docs/registration.md). Commented keys are unset (None): a",
        "# distance derived from the resolution through [settings], or an option left off.",
    ]
    for section, values in config.items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            if value is None:
                lines.append(f"# {key} =")
            else:
                lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def registration_options(
    config: dict[str, dict], flags: dict[str, Any], descriptor: Any = None
) -> dict[str, Any]:
    """``register()``'s keyword arguments from a loaded config and the command's flags
    (a flag given on the command line wins over the file).

    The global step (``"auto"`` resolved for ``descriptor`` as ``register()`` does) and
    every refinement are built from their sections; the settings from ``[settings]``.
    """
    from sklearn.base import clone

    from ..registration import RegistrationSettings
    from ..registration.defaults import resolve_global_method

    register = {**REGISTER_KEYS, **config.get("register", {})}
    register.update({k: v for k, v in flags.items() if v is not None})
    steps = _steps()
    if register["global_method"] == "auto":
        register["global_method"] = resolve_global_method("auto", descriptor)

    def build(name):
        if name in (None, "none"):
            return None
        if name not in steps:
            return name  # register() names an unknown step in its error
        step = steps[name](**config.get(name, {}))
        try:  # every value checked now, before any cloud is read
            step._validate_params()
        except (ValueError, TypeError) as exc:
            raise UsageError(f"[{name}]: {exc}") from None
        return step

    refine = register["refine"]
    chain = [refine] if isinstance(refine, str) else list(refine)
    chain = [build(r) for r in chain if r not in (None, "none")]
    if register["symmetry_check"]:
        if not chain:
            raise UsageError("--symmetry-check needs an ICP refinement (--refine)")
        from ..registration import SymmetryCheck

        chain.append(SymmetryCheck(refine=clone(chain[-1]), **config.get("symmetry_check", {})))
    settings = config.get("settings")
    try:
        settings = RegistrationSettings(**settings) if settings else None
    except (ValueError, TypeError) as exc:
        raise UsageError(f"[settings]: {exc}") from None
    return {
        "global_method": build(register["global_method"]),
        "refine": chain or None,
        "voxel_size": register["voxel_size"],
        "n_global_points": register["n_global_points"],
        "seed": register["seed"],
        "settings": settings,
    }
