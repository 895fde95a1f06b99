"""From a loaded config and a command's flags to the library's keyword arguments
(:func:`registration_options`, :func:`multiway_options`), and back to the config those
arguments are (:func:`used_config`)."""

from __future__ import annotations

from typing import Any

from ._common import UsageError
from ._config import OBJECT_PARAMETERS, REGISTER_KEYS, settings_section, step_classes, with_fpfh

__all__ = [
    "multiway_options",
    "reconstruct_options",
    "registration_options",
    "used_config",
]


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
    first = with_fpfh(chain[0][1] if chain[0][0] == "global" else None, register, descriptor)
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
        "random_state": register["random_state"],
        "settings": settings,
        "viewpoints": _viewpoints(register["viewpoints"], descriptor),
        "up": register["up"],
    }


def _viewpoints(given: Any, descriptor: Any) -> Any:
    """``[register] viewpoints`` as ``register()`` takes them: ``"none"`` is None, and
    ``"auto"`` stays only while the model is left to be chosen (``descriptor`` None);
    with a model given it means no sensor, as in ``register()``."""
    if given == "none" or (given == "auto" and descriptor is not None):
        return None
    return given


def _with_matchers(config: dict[str, dict]) -> dict[str, dict]:
    """``config`` with each ``[<step>.matcher]`` section made the step's ``matcher``
    parameter: its default matcher with the section's values."""
    built = {k: dict(v) for k, v in config.items()}
    for name, step_class in step_classes().items():
        if f"{name}.matcher" in config:
            matcher = step_class.default_matcher().set_params(**config[f"{name}.matcher"])
            built.setdefault(name, {})["matcher"] = matcher
    return built


def _check_unused_steps(config: dict[str, dict], used: set[str]) -> None:
    """Check the values of the step sections a run does not use as well: a bad value in
    a config file is an error whichever step the run picks."""
    built = _with_matchers(config)
    for name, step_class in step_classes().items():
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
    # The pairs are screened with FPFH only when told ("auto": the model's matches alone).
    told = config.get("register", {}).get("with_fpfh", "auto")
    flags = {**flags, "symmetry_check": False, "with_fpfh": False if told == "auto" else told}
    options = registration_options(config, flags, descriptor)
    if options.pop("up") is not None:
        raise UsageError("reconstruct takes no up direction ([register] up)")
    refine = options.pop("refine") or []
    if [step.name for step in refine] != ["point_to_plane"]:
        raise UsageError("reconstruct refines with point_to_plane ICP only ([register] refine)")
    if options["global_method"] is None:
        raise UsageError("reconstruct needs a global step ([register] global_method)")
    from ..registration.multiway import MAX_FREE_SPACE_VIOLATION, MIN_EDGE_FITNESS

    section = config.get("multiway", {})
    min_fitness = flags.get("min_fitness")
    if min_fitness is None:
        min_fitness = section.get("min_fitness", MIN_EDGE_FITNESS)
    options["min_fitness"] = min_fitness
    if not (isinstance(min_fitness, (int, float)) and 0 < min_fitness <= 1):
        raise UsageError(f"min_fitness must be in (0, 1], got {options['min_fitness']!r}")
    limit = flags.get("max_violation")
    if limit is None:
        limit = section.get("max_violation", MAX_FREE_SPACE_VIOLATION)
    if limit != "none" and not (isinstance(limit, (int, float)) and 0 <= limit <= 1):
        raise UsageError(f"max_violation must be in [0, 1] or 'none', got {limit!r}")
    options["max_violation"] = None if limit == "none" else limit
    return options


def _section_of(step: Any) -> tuple[str, dict[str, Any]]:
    """A step's section (its ``name``) and its parameters as a config gives them."""
    name = type(step).name
    if step_classes().get(name) is not type(step):
        raise TypeError(f"no config section for {type(step).__name__}")  # pragma: no cover
    params = step.get_params(deep=False)
    return name, {k: v for k, v in params.items() if k not in OBJECT_PARAMETERS}


def used_config(
    options: dict[str, Any], descriptor_section: dict[str, Any], extra: dict | None = None
) -> dict[str, dict[str, Any]]:
    """The config that gives ``options`` (:func:`registration_options` or
    :func:`multiway_options`) again: ``[register]`` with every step named, each step's
    section with every parameter, every setting, and ``[descriptor]`` (and ``[fpfh]``)
    as given. ``extra``: further sections (``[multiway]``)."""
    from ..registration import SymmetryCheck
    from ._config import own_matcher

    config: dict[str, dict[str, Any]] = {}
    register: dict[str, Any] = {
        "voxel_size": options["voxel_size"],
        "n_global_points": options["n_global_points"],
        "random_state": options["random_state"],
    }
    views = options.get("viewpoints")
    register["viewpoints"] = "none" if views is None else views  # None: no sensor known
    if options.get("up") is not None:
        register["up"] = options["up"]
    step = options["global_method"]
    if step is None:
        register["global_method"] = "none"
    else:
        register["global_method"], config_params = _section_of(step)
        config[register["global_method"]] = config_params
        if "matcher" in step.get_params(deep=False):
            register["with_fpfh"], matcher = own_matcher(step)
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
    config["settings"] = settings_section(options.get("settings"))
    config.update(extra or {})
    config["descriptor"] = {k: v for k, v in descriptor_section.items() if k != "fpfh"}
    if "fpfh" in descriptor_section:
        config["fpfh"] = descriptor_section["fpfh"]
    return config


def reconstruct_options(
    config: dict[str, dict], flags: dict[str, Any], descriptor: Any, section: dict, sequential: bool
) -> tuple[dict[str, Any], dict[str, Any]]:
    """``reconstruct``'s ``register_multiway()`` keyword arguments
    (:func:`multiway_options` and ``sequential``), and the record of its run."""
    from ._record import run_record

    options = {**multiway_options(config, flags, descriptor), "sequential": sequential}
    limit = "none" if options["max_violation"] is None else options["max_violation"]
    edges = {"min_fitness": options["min_fitness"], "max_violation": limit}
    used = used_config(options, section, {"multiway": edges})
    return options, run_record("reconstruct", used, descriptor)
