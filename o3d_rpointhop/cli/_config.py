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

__all__ = [
    "DESCRIPTOR_KEYS",
    "OBJECT_PARAMETERS",
    "REGISTER_KEYS",
    "default_config",
    "estimator_section",
    "load_config",
    "merge",
    "step_classes",
    "settings_section",
    "to_toml",
    "own_matcher",
    "with_fpfh",
]

#: ``[register]``: the arguments of ``register()`` (``register_multiway()`` takes all
#: but the refinement) the command line also has as flags, and ``with_fpfh``: the
#: consensus's matches beside FPFH's (:meth:`PooledMatcher.with_fpfh`): ``true``
#: always, ``"fallback"`` when the model's estimate is weak, ``false`` never, ``"auto"``
#: as ``register()`` chooses (the fallback for the scene model).
REGISTER_KEYS = {
    "global_method": "auto",
    "refine": "point_to_plane",
    "voxel_size": "auto",
    "n_global_points": "auto",
    "random_state": 0,
    "symmetry_check": False,
    "viewpoints": "auto",
    "up": None,
    "with_fpfh": "auto",
}
#: ``[descriptor]``: which descriptor a command describes with (``model``: a shipped
#: model's name or a model file; unset: the command's default) and on how many axes and
#: threads (unset: the model's own).
DESCRIPTOR_KEYS: dict[str, Any] = {
    "kind": "rpointhop",
    "model": None,
    "n_components": None,
    "n_jobs": None,
    "fpfh_weight": None,
}
#: Step parameters a file cannot give (objects, not values).
OBJECT_PARAMETERS = {"descriptor", "refine", "matcher"}
# Estimator parameters a file does not set (a progress bar is not a setting).
_NOT_SETTINGS = {"progress"}


def step_classes() -> dict[str, type]:
    from ..registration.pipeline import GLOBAL_METHODS, REFINE_METHODS

    return {**GLOBAL_METHODS, **REFINE_METHODS}


def settings_section(settings: Any = None) -> dict[str, Any]:
    """``[settings]``: every factor of ``settings`` (``None``: the defaults), the
    resolution left out (it is ``[register]``'s)."""
    from ..registration import RegistrationSettings

    settings = settings or RegistrationSettings()
    return {
        f.name: getattr(settings, f.name)
        for f in dataclasses.fields(RegistrationSettings)
        if f.name != "voxel_size"
    }


def default_config() -> dict[str, dict[str, Any]]:
    """Every section with its defaults (``None``: derived from the settings, or the
    command's own default)."""
    from ..descriptors import FPFHTransformer, RPointHopTransformer
    from ..registration.multiway import MAX_FREE_SPACE_VIOLATION, MIN_EDGE_FITNESS

    config: dict[str, dict[str, Any]] = {"register": dict(REGISTER_KEYS)}
    for name, cls in step_classes().items():
        params = cls().get_params(deep=False)
        config[name] = {k: v for k, v in params.items() if k not in OBJECT_PARAMETERS}
        if "matcher" in params:  # [<step>.matcher]: the step's default matcher
            config[f"{name}.matcher"] = cls.default_matcher().get_params()
    config["settings"] = settings_section()
    config["multiway"] = {
        "min_fitness": MIN_EDGE_FITNESS,
        "max_violation": MAX_FREE_SPACE_VIOLATION,
    }
    config["descriptor"] = dict(DESCRIPTOR_KEYS)
    config["fpfh"] = estimator_section(FPFHTransformer())
    config["fit"] = estimator_section(RPointHopTransformer())
    return config


def merge(config: dict, defaults: dict, section: str, key: str, value: Any, where: str) -> None:
    if (section, key) == ("register", "seed"):  # the library's former name
        from ._trust import log

        log.warning(f"{where}: [register] seed is now random_state (the library's name)")
        key = "random_state"
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
                if isinstance(value, dict):  # [step.matcher]
                    for inner, item in value.items():
                        merge(config, defaults, f"{section}.{key}", inner, item, path)
                else:
                    merge(config, defaults, section, key, value, path)
    for item in sets or []:
        name, sep, text = item.partition("=")
        section, dot, key = name.strip().rpartition(".")
        if not (sep and dot and key):
            raise UsageError(
                f"--set {item!r}: expected section.parameter=value (or step.matcher.parameter)"
            )
        try:  # a TOML value (numbers, true/false, quoted strings, arrays) or a bare word
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        merge(config, defaults, section, key.strip(), value, "--set")
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
    settings' resolution) are written commented out.

    Written here rather than with a TOML writer (tomllib only reads): the values are
    flat (numbers, booleans, strings, arrays of them), and the unset keys, which TOML
    cannot hold as values, are kept visible as comments, which writers do not emit."""
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


def estimator_section(estimator: Any) -> dict[str, Any]:
    """An estimator's parameters as a config section holds them (no progress bar, no
    thread count: those are not settings)."""
    params = estimator.get_params(deep=False)
    return {k: v for k, v in params.items() if k not in _NOT_SETTINGS and k != "n_jobs"}


def with_fpfh(step: Any, register: dict[str, Any], descriptor: Any) -> Any:
    """The global ``step`` as ``[register] with_fpfh`` makes it: ``true``, the consensus
    with its matches beside FPFH's, one consensus each, every hypothesis verified
    together (docs/low_overlap.md); ``"fallback"``, FPFH's only when the model's own
    estimate is weak; ``false``, the model's alone; ``"auto"``, as ``register()``
    builds it. Left as it is while the model is still to be chosen (``descriptor``
    None, ``global_method`` "auto"): the call after the choice decides."""
    from ..descriptors import FPFHTransformer
    from ..registration import ConsensusGlobal, PooledMatcher

    value = register["with_fpfh"]
    if not any(value is v for v in (True, False)) and value not in ("fallback", "auto"):
        raise UsageError(
            f"[register] with_fpfh must be true, false, 'fallback' or 'auto', got {value!r}"
        )
    if value == "auto" or (descriptor is None and register["global_method"] == "auto"):
        return step
    if value is False:
        if isinstance(step, ConsensusGlobal):
            pooled, own = own_matcher(step)
            if pooled:
                return step.set_params(matcher=own)
        return step
    if isinstance(descriptor, FPFHTransformer):
        raise UsageError("--with-fpfh adds FPFH beside R-PointHop; --descriptor fpfh has it")
    if not isinstance(step, ConsensusGlobal):
        name = "none" if step is None else type(step).name
        raise UsageError(
            f"--with-fpfh needs the consensus as the global step, got {name} (--global "
            "consensus; the scene model's default is the consensus)"
        )
    combine = "hypotheses" if value is True else "fallback"
    return step.set_params(matcher=PooledMatcher.with_fpfh(own_matcher(step)[1], combine=combine))


def own_matcher(step: Any) -> tuple[bool | str, Any]:
    """A global step's matcher as a config records it: whether FPFH's matches are
    beside it (``with_fpfh``: true, ``"fallback"`` or false), and the matcher of the
    step's own descriptor."""
    from ..registration import PooledMatcher

    matcher = step.matcher if step.matcher is not None else step.default_matcher()
    if isinstance(matcher, PooledMatcher):
        return "fallback" if matcher.combine == "fallback" else True, matcher.parts[0][2]
    return False, matcher
