"""Configuration files for the command line: one TOML section per step and one for the
settings, keys are the library's parameter names (as KISS-ICP's config is), with
``--set section.parameter=value`` for one-off changes and ``o3d-rpointhop config`` to
print the defaults as a file to start from."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

from ._common import DESCRIPTORS, CommandError, UsageError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "default_config",
    "descriptor_from",
    "estimator_section",
    "load_config",
    "multiway_options",
    "registration_options",
    "run_record",
    "to_toml",
    "write_record",
]

#: ``[register]``: the arguments of ``register()`` (``register_multiway()`` takes all
#: but the refinement) the command line also has as flags.
REGISTER_KEYS = {
    "global_method": "auto",
    "refine": "point_to_plane",
    "voxel_size": "auto",
    "n_global_points": "auto",
    "seed": 0,
    "symmetry_check": False,
    "viewpoints": None,
    "up": None,
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
# Step parameters a file cannot give (objects, not values).
_OBJECT_PARAMETERS = {"descriptor", "refine", "matcher"}
# Estimator parameters a file does not set (a progress bar is not a setting).
_NOT_SETTINGS = {"progress"}


def _steps() -> dict[str, type]:
    from ..registration.pipeline import GLOBAL_METHODS, REFINE_METHODS

    return {**GLOBAL_METHODS, **REFINE_METHODS}


def _settings_section(settings: Any = None) -> dict[str, Any]:
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
    from ..registration.multiway import MIN_EDGE_FITNESS

    config: dict[str, dict[str, Any]] = {"register": dict(REGISTER_KEYS)}
    for name, cls in _steps().items():
        params = cls().get_params(deep=False)
        config[name] = {k: v for k, v in params.items() if k not in _OBJECT_PARAMETERS}
        if "matcher" in params:  # [<step>.matcher]: the step's default matcher
            config[f"{name}.matcher"] = cls.default_matcher().get_params()
    config["settings"] = _settings_section()
    config["multiway"] = {"min_fitness": MIN_EDGE_FITNESS}
    config["descriptor"] = dict(DESCRIPTOR_KEYS)
    config["fpfh"] = estimator_section(FPFHTransformer())
    config["fit"] = estimator_section(RPointHopTransformer())
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
                if isinstance(value, dict):  # [step.matcher]
                    for inner, item in value.items():
                        _merge(config, defaults, f"{section}.{key}", inner, item, path)
                else:
                    _merge(config, defaults, section, key, value, path)
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


def registration_options(
    config: dict[str, dict], flags: dict[str, Any], descriptor: Any = None
) -> dict[str, Any]:
    """``register()``'s keyword arguments from a loaded config and the command's flags
    (a flag given on the command line wins over the file).

    The global step (``"auto"`` resolved for ``descriptor`` as ``register()`` does) and
    every refinement are built from their sections; the settings from ``[settings]``.
    :func:`used_config` gives back the config these options are.
    """
    from ..registration import RegistrationSettings
    from ..registration.pipeline import build_chain

    register = {**REGISTER_KEYS, **config.get("register", {})}
    register.update({k: v for k, v in flags.items() if v is not None})
    refine = register["refine"]
    names = [refine] if isinstance(refine, str) else list(refine)
    names = [r for r in names if r not in (None, "none")]
    if register["symmetry_check"]:
        if not names:
            raise UsageError("--symmetry-check needs an ICP refinement (--refine)")
        names.append("symmetry_check")
    global_method = register["global_method"]
    try:
        chain = build_chain(
            None if global_method == "none" else global_method,
            names,
            descriptor,
            _with_matchers(config),
        )
    except (ValueError, TypeError) as exc:
        raise UsageError(f"[register]: {exc}") from None
    for _, step in chain:  # every value checked now, before any cloud is read
        try:
            step.validate()
        except (ValueError, TypeError) as exc:
            raise UsageError(f"[{_section_of(step)[0]}]: {exc}") from None
    _check_unused_steps(config, {_section_of(step)[0] for _, step in chain})
    first = chain[0][1] if chain[0][0] == "global" else None
    rest = [step for name, step in chain if name != "global"]
    settings = config.get("settings")
    try:
        settings = RegistrationSettings(**settings) if settings else None
    except (ValueError, TypeError) as exc:
        raise UsageError(f"[settings]: {exc}") from None
    return {
        "global_method": first,
        "refine": rest or None,
        "voxel_size": register["voxel_size"],
        "n_global_points": register["n_global_points"],
        "seed": register["seed"],
        "settings": settings,
        "viewpoints": register["viewpoints"],
        "up": register["up"],
    }


def _with_matchers(config: dict[str, dict]) -> dict[str, dict]:
    """``config`` with each ``[<step>.matcher]`` section made the step's ``matcher``
    parameter: its default matcher with the section's values."""
    built = {k: dict(v) for k, v in config.items()}
    for name, step_class in _steps().items():
        if f"{name}.matcher" in config:
            matcher = step_class.default_matcher().set_params(**config[f"{name}.matcher"])
            built.setdefault(name, {})["matcher"] = matcher
    return built


def _check_unused_steps(config: dict[str, dict], used: set[str]) -> None:
    """Check the values of the step sections a run does not use as well: a bad value in
    a config file is an error whichever step the run picks."""
    built = _with_matchers(config)
    for name, step_class in _steps().items():
        if name in built and name not in used:
            try:
                step_class(**built[name]).validate()
            except (ValueError, TypeError) as exc:
                raise UsageError(f"[{name}] (not used by this run): {exc}") from None


def multiway_options(
    config: dict[str, dict], flags: dict[str, Any], descriptor: Any = None
) -> dict[str, Any]:
    """``register_multiway()``'s keyword arguments from a loaded config and the command's
    flags: ``[register]``'s global step (built from its section), resolution and seed,
    ``[multiway]``'s edge threshold and ``[settings]``. Multiway refines with
    point-to-plane ICP (the pose graph needs its information matrices), so a refinement
    other than that is refused."""
    options = registration_options(config, {**flags, "symmetry_check": False}, descriptor)
    if options.pop("up") is not None:
        raise UsageError("reconstruct takes no up direction ([register] up)")
    refine = options.pop("refine") or []
    if [step.name for step in refine] != ["point_to_plane"]:
        raise UsageError("reconstruct refines with point_to_plane ICP only ([register] refine)")
    if options["global_method"] is None:
        raise UsageError("reconstruct needs a global step ([register] global_method)")
    from ..registration.multiway import MIN_EDGE_FITNESS

    min_fitness = flags.get("min_fitness")
    if min_fitness is None:
        min_fitness = config.get("multiway", {}).get("min_fitness", MIN_EDGE_FITNESS)
    options["min_fitness"] = min_fitness
    if not (isinstance(min_fitness, (int, float)) and 0 < min_fitness <= 1):
        raise UsageError(f"min_fitness must be in (0, 1], got {options['min_fitness']!r}")
    return options


def _section_of(step: Any) -> tuple[str, dict[str, Any]]:
    """A step's section (its ``name``) and its parameters as a config gives them."""
    name = type(step).name
    if _steps().get(name) is not type(step):
        raise TypeError(f"no config section for {type(step).__name__}")  # pragma: no cover
    params = step.get_params(deep=False)
    return name, {k: v for k, v in params.items() if k not in _OBJECT_PARAMETERS}


def used_config(
    options: dict[str, Any], descriptor_section: dict[str, Any], extra: dict | None = None
) -> dict[str, dict[str, Any]]:
    """The config that gives ``options`` (:func:`registration_options` or
    :func:`multiway_options`) again: ``[register]`` with every step named, each step's
    section with every parameter, every setting, and ``[descriptor]`` (and ``[fpfh]``)
    as given. ``extra``: further sections (``[multiway]``)."""
    from ..registration import SymmetryCheck

    config: dict[str, dict[str, Any]] = {}
    register: dict[str, Any] = {
        "voxel_size": options["voxel_size"],
        "n_global_points": options["n_global_points"],
        "seed": options["seed"],
    }
    for key in ("viewpoints", "up"):
        if options.get(key) is not None:
            register[key] = options[key]
    step = options["global_method"]
    if step is None:
        register["global_method"] = "none"
    else:
        register["global_method"], config_params = _section_of(step)
        config[register["global_method"]] = config_params
        if "matcher" in step.get_params(deep=False):
            matcher = step.matcher if step.matcher is not None else step.default_matcher()
            config[f"{register['global_method']}.matcher"] = matcher.get_params()
    if "refine" in options:
        chain = list(options["refine"] or [])
        register["symmetry_check"] = bool(chain) and isinstance(chain[-1], SymmetryCheck)
        if register["symmetry_check"]:
            check = chain.pop()
            config["symmetry_check"] = {
                k: v for k, v in check.get_params(deep=False).items() if k != "refine"
            }
        names = []
        for refine in chain:
            name, params = _section_of(refine)
            names.append(name)
            config[name] = params
        register["refine"] = names[0] if len(names) == 1 else (names or "none")
    config = {"register": register, **config}
    config["settings"] = _settings_section(options.get("settings"))
    config.update(extra or {})
    config["descriptor"] = {k: v for k, v in descriptor_section.items() if k != "fpfh"}
    if "fpfh" in descriptor_section:
        config["fpfh"] = descriptor_section["fpfh"]
    return config


def descriptor_from(
    config: dict[str, dict],
    kind: str | None,
    model: str | None,
    n_components: int | None = None,
    *,
    registering: bool = True,
) -> tuple[Any, dict[str, Any]]:
    """The descriptor a command describes with, and the ``[descriptor]`` section that
    names it (with ``"fpfh"``: FPFH's parameters).

    Flags (``--descriptor``, ``--model``, ``--n-components``; ``None`` when not given)
    win over ``[descriptor]``; ``[fpfh]`` configures FPFH. ``"rpointhop+fpfh"``: the
    model and FPFH side by side (:class:`~o3d_rpointhop.DescriptorUnion`), FPFH weighing
    ``fpfh_weight`` (:data:`~o3d_rpointhop.registration.defaults.SCENE_FPFH_WEIGHT`
    unless given). ``None`` as the descriptor
    leaves the choice to the library (its default descriptor), unless axes or threads
    are set, which then apply to that default. A model named by ``--model`` is what
    ``RPointHopTransformer.pretrained(name)`` gives (``--n-components`` its
    ``n_components``); with ``registering`` off (``describe``) the default is the
    paper's model.
    """
    section = {**DESCRIPTOR_KEYS, **config.get("descriptor", {})}
    for key, value in (("kind", kind), ("model", model), ("n_components", n_components)):
        if value is not None:
            section[key] = value
    if section["kind"] not in DESCRIPTORS:
        raise UsageError(
            f"[descriptor]: kind must be one of {', '.join(map(repr, DESCRIPTORS))}, "
            f"got {section['kind']!r}"
        )
    if section["fpfh_weight"] is not None and section["kind"] != "rpointhop+fpfh":
        raise UsageError("[descriptor]: fpfh_weight applies to the rpointhop+fpfh descriptor")
    if section["kind"] == "fpfh":
        if section["model"] is not None:
            raise CommandError("--model applies to the rpointhop descriptor, not fpfh")
        fpfh = _fpfh_from(config, section["n_jobs"])
        return fpfh, {**section, "fpfh": estimator_section(fpfh)}
    if section["kind"] == "rpointhop+fpfh":
        from ..descriptors import DescriptorUnion
        from ..registration.defaults import SCENE_FPFH_WEIGHT

        if section["fpfh_weight"] is None:
            section["fpfh_weight"] = SCENE_FPFH_WEIGHT
        fpfh = _fpfh_from(config, section["n_jobs"])
        union = DescriptorUnion(
            [("rpointhop", _rpointhop_from(section, registering)), ("fpfh", fpfh)],
            transformer_weights={"fpfh": section["fpfh_weight"]},
        )
        try:
            union.validate()
        except ValueError as exc:
            raise UsageError(f"[descriptor]: {exc}") from None
        return union, {**section, "fpfh": estimator_section(fpfh)}
    unset = (section["model"], section["n_components"], section["n_jobs"]) == (None,) * 3
    if registering and unset:
        return None, section
    return _rpointhop_from(section, registering), section


def _fpfh_from(config: dict[str, dict], n_jobs: int | None) -> Any:
    """FPFH as ``[fpfh]`` configures it."""
    from ..descriptors import FPFHTransformer

    params = dict(config.get("fpfh", {}))
    descriptor = FPFHTransformer(**params, **({} if n_jobs is None else {"n_jobs": n_jobs}))
    try:
        descriptor.validate()
    except (ValueError, TypeError) as exc:
        raise UsageError(f"[fpfh]: {exc}") from None
    return descriptor


def _rpointhop_from(section: dict[str, Any], registering: bool) -> Any:
    """The R-PointHop model ``section`` names, on its axes and threads (``section`` is
    completed with what was left to the defaults): no model named is the library's
    default model when registering, the paper's model otherwise."""
    from ..registration.defaults import DEFAULT_MODEL
    from ._common import load_model

    if section["model"] is None:
        section["model"] = DEFAULT_MODEL if registering else "modelnet40"
    name, n_jobs = section["model"], section["n_jobs"]
    try:
        descriptor = load_model(name, section["n_components"])
        if n_jobs is not None:
            descriptor.set_params(n_jobs=n_jobs)
            descriptor.validate()
    except (ValueError, TypeError) as exc:
        if isinstance(exc, ValueError) and not Path(str(name)).exists():
            raise
        raise UsageError(f"[descriptor]: {exc}") from None
    return descriptor


def estimator_section(estimator: Any) -> dict[str, Any]:
    """An estimator's parameters as a config section holds them (no progress bar, no
    thread count: those are not settings)."""
    params = estimator.get_params(deep=False)
    return {k: v for k, v in params.items() if k not in _NOT_SETTINGS and k != "n_jobs"}


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
            _merge(out, defaults, section, key, value, path)
    return out
