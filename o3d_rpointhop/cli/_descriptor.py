"""The descriptor a command describes or registers with, from its flags and the
``[descriptor]`` and ``[fpfh]`` sections: what ``RPointHopTransformer.pretrained(name)``,
``FPFHTransformer`` and ``DescriptorUnion`` give in Python, nothing more."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ._common import DESCRIPTORS, CommandError, UsageError
from ._config import DESCRIPTOR_KEYS, estimator_section

__all__ = ["chosen_descriptor", "descriptor_from"]


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
    unless given). ``None`` as the descriptor leaves the choice to the library
    (:func:`chosen_descriptor`, from the clouds: ``--model auto``, the default of
    ``register`` and ``reconstruct``), unless axes are set, which then apply to the
    object model. A model named by ``--model`` is what
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
    if section["model"] == "auto":
        if not registering:
            raise UsageError("--model auto applies to register and reconstruct")
        if section["n_components"] is not None:
            raise UsageError("--n-components applies to a named model, not --model auto")
        return None, section
    if registering and (section["model"], section["n_components"]) == (None, None):
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


def chosen_descriptor(
    section: dict[str, Any],
    viewpoints: Any,
    clouds: list[Any],
    names: list[str],
    multiway: bool = False,
) -> tuple[Any, str | list, dict[str, Any]]:
    """The shipped model and viewpoints ``register(descriptor="auto")`` would use for
    ``clouds`` (a command whose model was left to the library: ``descriptor_from``
    gave None), on ``[descriptor]``'s threads; the viewpoints as the ``--viewpoints``
    flag says them (``"none"`` for no sensor), and the choice, JSON-ready. With
    ``multiway``, the model on the axes ``register_multiway(descriptor="auto")`` gives
    it (:func:`~o3d_rpointhop.registration.multiway.chosen_model`)."""
    from ..registration.model_choice import resolve_model
    from ..registration.multiway import chosen_model
    from ._trust import log

    try:
        descriptor, views, choice = resolve_model("auto", viewpoints, clouds, names)
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    if multiway:
        descriptor, choice = chosen_model(descriptor, choice)
    if section.get("n_jobs") is not None:
        descriptor = descriptor.set_params(n_jobs=section["n_jobs"])
    axes = "" if choice.axes is None else f" on {choice.axes} axes"
    log.info("model: %s%s, viewpoints %s (%s)", choice.model, axes, views, choice.reason)
    return descriptor, "none" if views is None else views, choice.as_dict()
