"""One vocabulary: the same concept has the same name in every public function and on the
command line, every method gives back one result shape, and the methods layer routes
parameters by name."""

import importlib
import inspect

import numpy as np
import pytest

import lidarstat
from lidarstat.cli._app import build_parser
from lidarstat.errors import InvalidParameterError
from lidarstat.pipeline import METHODS, SEGMENTATIONS, method_function, segmentation

SUBPACKAGES = ("io", "neighbors", "features", "stats", "classify", "segment", "pipeline",
               "report", "synth")

#: Spellings of a concept that has another name in lidarstat: name -> the name to use.
#: (``bandwidth`` stays where it is the density estimate's or the tricube kernel's
#: bandwidth of a fit on given neighbourhoods, a concept of its own; ``k`` for a region
#: growing's graph is ``grow_k``.)
SYNONYMS = {
    "min_size": "min_points", "min_cluster": "min_points", "tile_size": "window",
    "min_tile_size": "min_window", "alpha_residual": "envelope_alpha",
    "threshold": "search", "normal_angle": "max_angle", "noise_estimate": "(removed)",
    "curvature_frame": "frame", "curvature_noise": "noise", "jet_radius": "radius",
    "n_neighbors": "k", "knn": "k", "min_neighbours": "min_neighbors", "seed": "rng",
    "level": "alpha", "significance": "alpha", "scanner": "sensor", "noise_sigma": "sigma",
}


def _public_functions():
    for name in SUBPACKAGES:
        module = importlib.import_module(f"lidarstat.{name}")
        for attr in module.__all__:
            obj = getattr(module, attr)
            if inspect.isfunction(obj) or inspect.isfunction(inspect.unwrap(obj)):
                yield f"lidarstat.{name}.{attr}", inspect.unwrap(obj)


@pytest.mark.parametrize("qualname, func", list(_public_functions()),
                         ids=[q for q, _ in _public_functions()])
def test_no_public_function_uses_another_name_for_a_concept(qualname, func):
    params = set(inspect.signature(func).parameters)
    wrong = {p: SYNONYMS[p] for p in params if p in SYNONYMS}
    if qualname == "lidarstat.report.run_demo":  # the demo's seed is the scene's seed
        wrong.pop("seed", None)
    assert not wrong, f"{qualname}: use {wrong}"


def _options_of(parser):
    old = parser.get_default("_deprecated") or {}
    for action in parser._actions:
        for option in action.option_strings:
            if option not in old:
                yield option, action


def test_no_cli_option_uses_another_name_for_a_concept():
    sub = next(a for a in build_parser()._actions if a.choices and isinstance(a.choices, dict))
    bad = []
    for command, parser in sub.choices.items():
        for option, _ in _options_of(parser):
            dest = option.lstrip("-").replace("-", "_")
            # on the command line the random generator's seed is --seed (library: rng)
            if dest in SYNONYMS and dest != "seed":
                bad.append(f"{command} {option} (use {SYNONYMS[dest]})")
    assert not bad


def test_every_method_gives_one_result_shape():
    from lidarstat.synth import make_hip_roof_scene

    scene = make_hip_roof_scene(rng=0, density=6.0)
    xyz = scene.xyz
    args = {"curvature": {"radius": 1.5}, "jets": {"radius": 2.0}, "ridges": {"radius": 2.0},
            "covariance": {"k": 30}, "moments": {"window": 16.0}}
    inputs = {"moments": {"intensity": scene.attributes["intensity"]}}
    assert set(args) == set(METHODS)
    for name, kwargs in args.items():
        res = method_function(name)(xyz, **inputs.get(name, {}), **kwargs)
        fields = res.to_fields()
        assert fields and all(np.asarray(v).shape[0] == len(xyz) for v in fields.values())
        assert isinstance(res.summary(), str) and res.summary()
        assert isinstance(res.params, dict)
        for k, v in kwargs.items():
            assert res.params.get(k) == v, f"{name}: params[{k!r}] = {res.params.get(k)!r}"
        assert getattr(lidarstat, name) is method_function(name)


def test_segmentation_routes_parameters_and_refuses_unknown_ones():
    from lidarstat.synth import make_hip_roof_scene

    scene = make_hip_roof_scene(rng=1, density=6.0)
    seg = segmentation(scene.xyz, method="covariance", k=30, min_points=20)
    assert seg.params["min_points"] == 20 and seg.labels.shape == (len(scene.xyz),)
    with pytest.raises(InvalidParameterError, match="takes no parameter min_size"):
        segmentation(scene.xyz, method="covariance", min_size=20)
    with pytest.raises(InvalidParameterError, match="unknown segmentation method"):
        segmentation(scene.xyz, method="nope")
    assert set(SEGMENTATIONS) == set(
        next(a for a in build_parser()._actions if a.choices and isinstance(a.choices, dict))
        .choices["segment"]._option_string_actions["--method"].choices)
