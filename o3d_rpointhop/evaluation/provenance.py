"""What produced a benchmark result: the library, its commit, the thread budget, and for
every method its descriptor (class, model name, content hash, parameters) and options.

Every runner writes :func:`run_provenance` into its result under ``"provenance"``;
:func:`read_results` refuses a result file without it, so a table cannot be rebuilt
from numbers that do not say what made them.
"""

from __future__ import annotations

import json
from importlib import metadata
from pathlib import Path
from typing import Any

from sklearn.base import BaseEstimator

from .._utils.provenance import json_safe, library_facts
from ..descriptors import FPFHTransformer, RPointHopTransformer, descriptor_identity
from ._common import machine_facts
from .methods import METHODS, shipped_scene_model
from .peers import open3d_recipe_descriptor

__all__ = [
    "REQUIRED",
    "check_provenance",
    "descriptor_provenance",
    "model_identity",
    "multiway_provenance",
    "read_results",
    "rooms_provenance",
    "run_provenance",
]

#: The keys every result's ``"provenance"`` holds.
REQUIRED = ("o3d_rpointhop", "commit", "open3d", "numpy", "python", "threads", "methods")


def model_identity(model: RPointHopTransformer) -> dict:
    """A fitted R-PointHop model as a record names it
    (:func:`~o3d_rpointhop.descriptors.descriptor_identity`)."""
    return descriptor_identity(model)


def _open3d_fpfh() -> dict:
    return {
        "class": "open3d.pipelines.registration.compute_fpfh_feature",
        "params": "normals: radius 2 voxels, 30 neighbours; features: radius 5 voxels, "
        "100 neighbours (Open3D's global registration tutorial)",
    }


def _library_fpfh() -> dict:
    return descriptor_identity(FPFHTransformer())


def _kiss_matcher() -> dict:
    try:
        version = metadata.version("kiss-matcher")
    except metadata.PackageNotFoundError:
        version = None
    return {"class": "kiss_matcher.KISSMatcher (Faster-PFH)", "version": version}


#: The non-R-PointHop descriptors, by :attr:`~.methods.Method.descriptor`.
_FEATURES = {
    "open3d-fpfh": _open3d_fpfh,
    "fpfh": _library_fpfh,
    "kiss-matcher": _kiss_matcher,
    "none": lambda: {"class": None},
}


def _option(value: Any) -> Any:
    """How a record names a ``register()`` option: an estimator (a global step) by its
    parameters on one line, as scikit-learn prints them, a function by its name."""
    if isinstance(value, BaseEstimator):
        return " ".join(repr(value).split())
    return getattr(value, "__name__", value) if callable(value) else value


def _method_entry(name: str, given: RPointHopTransformer, loso: dict, identity) -> dict:
    """One method's entry; ``identity`` is :func:`model_identity`, memoised per run."""
    method = METHODS[name]
    entry: dict = {"description": method.description}
    options = getattr(method.run, "options", None)
    if options is not None:
        entry["options"] = json_safe({k: _option(v) for k, v in options.items()})
    if method.descriptor == "union":
        entry["descriptor"] = descriptor_identity(method.run.describe_with())
    elif method.model == "given":
        entry["descriptor"] = identity(given)
    elif method.model == "scene":
        entry["descriptor"] = identity(shipped_scene_model())
    elif method.model == "recipe":
        entry["descriptor"] = identity(open3d_recipe_descriptor())
    elif method.model == "loso":
        entry["descriptor"] = {
            "per_scene": {scene: identity(m) for scene, m in sorted(loso.items())}
        }
    else:
        entry["descriptor"] = _FEATURES[method.descriptor]()
    return entry


def _run_facts() -> dict:
    """What every provenance holds besides its methods: the library versions
    (:func:`~._common.machine_facts`'s), the commit and the thread budget."""
    return {**library_facts(), "threads": machine_facts()["thread_budget"]}


def _memoised_identity():
    """:func:`model_identity` computed once per model object (one run's models). The
    memo holds the models too, so that no id is reused by another model meanwhile."""
    seen: dict[int, tuple[RPointHopTransformer, dict]] = {}

    def identity(model: RPointHopTransformer) -> dict:
        if id(model) not in seen:
            seen[id(model)] = (model, model_identity(model))
        return seen[id(model)][1]

    return identity


def run_provenance(methods, model: RPointHopTransformer, loso: dict | None = None) -> dict:
    """The provenance of a run of ``methods`` with the benchmark's ``model`` (and the
    leave-one-scene-out models by scene, when a method uses them)."""
    identity = _memoised_identity()
    return {
        **_run_facts(),
        "methods": {name: _method_entry(name, model, loso or {}, identity) for name in methods},
    }


def descriptor_provenance(descriptors: dict, threads: str | None = None) -> dict:
    """The provenance of a script's run: ``descriptors`` maps each method to its
    descriptor, a fitted ``RPointHopTransformer`` (named by :func:`model_identity`) or
    a dict that describes another one; ``threads`` overrides the thread budget (a
    script that measures both says so)."""
    identity = _memoised_identity()
    facts = _run_facts()
    if threads is not None:
        facts["threads"] = threads
    return {
        **facts,
        "methods": {
            name: {"descriptor": d if isinstance(d, dict) else identity(d)}
            for name, d in descriptors.items()
        },
    }


def multiway_provenance(methods) -> dict:
    """:func:`run_provenance` for the scan-set benchmark's methods (``rpointhop``:
    ``register_multiway``'s default model; ``fpfh``: this library's FPFH;
    ``open3d-recipe``: Open3D's tutorial FPFH)."""
    from ..registration.defaults import default_descriptor

    kinds = {
        "rpointhop": default_descriptor,
        "fpfh": _FEATURES["fpfh"],
        "open3d-recipe": _FEATURES["open3d-fpfh"],
    }
    return descriptor_provenance({name: kinds[name]() for name in methods})


def rooms_provenance(methods) -> dict:
    """The provenance of a rooms benchmark run (``auto``: both shipped models it chooses
    between; ``fpfh`` and ``open3d-recipe`` as in :func:`multiway_provenance`)."""
    from ..registration.model_choice import MODELS

    descriptors: dict[str, Any] = {}
    for name in methods:
        if name == "auto":
            for model in MODELS:
                descriptors[f"auto-{model}"] = RPointHopTransformer.pretrained(model)
        else:
            descriptors[name] = _FEATURES["fpfh" if name == "fpfh" else "open3d-fpfh"]()
    return descriptor_provenance(descriptors)


def _methods_of(results: dict) -> set[str]:
    """Every method a result holds records of."""
    names: set[str] = set()
    for protocol in results.get("protocols", {}).values():
        names |= set(protocol.get("records", {}))
    for entry in results.get("objects", {}).values():
        names |= set(entry.get("methods", {}))
    return names


def check_provenance(results: dict, where: str = "result") -> None:
    """Raise ValueError unless ``results`` names what produced every method in it."""
    found = results.get("provenance") if isinstance(results, dict) else None
    if not isinstance(found, dict):
        raise ValueError(f"{where} records no provenance: it cannot say what produced it")
    missing = [key for key in REQUIRED if key not in found]
    if missing:
        raise ValueError(f"{where}: its provenance lacks {missing}")
    unnamed = sorted(_methods_of(results) - set(found["methods"]))
    if unnamed:
        raise ValueError(f"{where}: its provenance does not name the methods {unnamed}")
    for name, entry in found["methods"].items():
        if "descriptor" not in entry:
            raise ValueError(f"{where}: method {name!r} names no descriptor")


def read_results(path) -> dict:
    """A result file written by a benchmark, refused (ValueError) without provenance."""
    path = Path(path)
    results = json.loads(path.read_text())
    check_provenance(results, str(path))
    return results
