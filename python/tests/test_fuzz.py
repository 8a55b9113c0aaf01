"""A seeded corpus of API misuse: wrong types, NaN and infinities, odd
shapes and dtypes, missing and non-regular files, and calls out of order.
Every call must return or raise an ordinary exception (an ``Exception``
with a message); a Rust panic surfaces as ``PanicException``, which derives
from ``BaseException`` and is what this corpus hunts."""

import pathlib
import random
import warnings

import numpy as np

import skinpatch

SEED = 20261207
CASES = 1500

NAN, INF = float("nan"), float("inf")


def values(rng, tmp, root, writable=False):
    """One argument of any kind a careless caller passes; with `writable`,
    no path outside `tmp` (a write target must not reach the repository)."""
    pool = [
        None,
        0,
        -1,
        2**70,
        1.5,
        NAN,
        INF,
        -INF,
        "",
        "x",  # relative: the test runs in its temporary folder
        b"bytes",
        [],
        [1, 2],
        (1.0, 2.0, 3.0),
        (NAN, 0.0, 1.0),
        (0.0, 0.0, INF),
        (1.0, 2.0),
        ("a", "b", "c"),
        {},
        {"k": 1},
        object(),
        True,
        np.float32(2.5),
        np.int64(3),
        np.zeros(0),
        np.zeros(3),
        np.full(3, NAN),
        np.zeros((2, 3)),
        np.zeros(3, dtype=np.complex128),
        np.array(["a", "b", "c"]),
        np.array([None, 1, 2], dtype=object),
        np.array(1.0),
        tmp / "missing.toml",
        tmp,
        pathlib.Path("/dev/null"),
    ]
    if not writable:
        pool += [
            root / "tests/fixtures/press_small.toml",
            root / "meshes/patch_3k.node",
            str(root / "meshes/patch_3k.ele"),
        ]
    return rng.choice(pool)


KEYS = [
    "probe.friction",
    "time.frame_rate_hz",
    "time.duration_s",
    "material.dermis.poisson_ratio",
    "material.dermis.youngs_modulus_kpa",
    "solver.max_newton_iterations",
    "mesh.file",
    "output.dir",
    "probe",
    "nonexistent.key",
    "",
    "a..b",
    "time",
]


def overrides(rng, tmp, root):
    if rng.random() < 0.2:
        return values(rng, tmp, root)
    return {rng.choice(KEYS): values(rng, tmp, root) for _ in range(rng.randint(1, 3))}


def arrays(rng, mesh, tmp, root):
    """Point or cell data: right and wrong lengths, shapes and dtypes."""
    if rng.random() < 0.2:
        return values(rng, tmp, root)
    n = rng.choice([mesh.num_vertices, mesh.num_tets, 0, 1, mesh.num_vertices + 1])
    shape = rng.choice([(n,), (n, 3), (n, 2), (n, 3, 3), (n, 9), (3, n)])
    dtype = rng.choice([np.float64, np.float32, np.int32, np.int64, np.uint8, bool, np.complex64])
    data = np.zeros(shape, dtype=dtype)
    if rng.random() < 0.3 and data.dtype.kind == "f" and data.size:
        data.flat[0] = rng.choice([NAN, INF])
    name = rng.choice(["a", "", "x" * 300, "é", "with space", "a/b"])
    return {name: data}


def fuzz_case(rng, tmp, root, scenario, mesh):
    """One misuse, as a list of calls (each a zero-argument function)."""
    kind = rng.randrange(7)
    if kind == 0:
        path = values(rng, tmp, root)
        return [lambda: skinpatch.Scenario.load(path, overrides(rng, tmp, root))]
    if kind == 1:
        return [lambda: skinpatch.read_mesh(values(rng, tmp, root))]
    if kind == 2:
        target = rng.choice([tmp / "out.vtu", tmp, values(rng, tmp, root, writable=True)])
        which = rng.choice([mesh, values(rng, tmp, root)])
        return [
            lambda: skinpatch.write_vtu(
                target,
                which,
                point_data=arrays(rng, mesh, tmp, root),
                cell_data=arrays(rng, mesh, tmp, root),
            )
        ]
    if kind == 3:
        return [
            lambda: skinpatch.neutral_map(values(rng, tmp, root)),
            lambda: skinpatch.fit(values(rng, tmp, root)),
        ]
    if kind == 4:
        return [
            lambda: mesh.write_vtu(
                rng.choice([tmp / "m.vtu", values(rng, tmp, root, writable=True)]),
                point_data=arrays(rng, mesh, tmp, root),
                cell_data=arrays(rng, mesh, tmp, root),
            )
        ]
    # A run: odd constructor arguments, then calls in a random order.
    args = rng.choice(
        [
            (scenario,),
            # Not True: outputs would go to the scenario's own folder.
            (scenario, rng.choice([None, 0, 1.5, "x", [], NAN, np.zeros(3)])),
            (scenario, True, rng.choice([tmp / "run", values(rng, tmp, root, writable=True)])),
            (values(rng, tmp, root),),
        ]
    )
    state = {}

    def start():
        state["run"] = skinpatch.Run(*args)

    def step():
        run = state.get("run")
        if run is not None:
            kw = {}
            if rng.random() < 0.7:
                kw["probe_target"] = values(rng, tmp, root)
            if rng.random() < 0.3:
                kw["probe_axis"] = values(rng, tmp, root)
            state["frame"] = run.step(**kw)

    def finish():
        if "run" in state:
            state["run"].finish()

    def frame_calls():
        frame = state.get("frame")
        if frame is not None:
            _ = frame.metrics, frame.stresses, frame.contact_pressure, frame.probe_centre
            target = values(rng, tmp, root, writable=True)
            rng.choice([frame.deformed_map, lambda: frame.write_vtu(target)])()

    def properties():
        run = state.get("run")
        if run is not None:
            _ = run.next_frame, run.scenario_frames, run.frame_dt
            next(run)

    calls = [start] + [rng.choice([step, step, finish, frame_calls, properties]) for _ in range(4)]
    return calls


def test_misuse_of_the_api_never_panics(root, tmp_path, monkeypatch):
    # Relative paths (an output folder "x") land in the temporary folder.
    monkeypatch.chdir(tmp_path)
    rng = random.Random(SEED)
    scenario = skinpatch.Scenario.load(
        root / "tests/fixtures/press_small.toml", {"time.frame_rate_hz": 3.0}
    )
    mesh = scenario.mesh
    counts = {"returned": 0, "raised": 0}
    panics = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run_corpus(rng, tmp_path, root, scenario, mesh, counts, panics)
    assert not panics, "\n".join(panics[:20])
    # Nothing taken in silently: a complex value cast to real, say.
    complex_warning = getattr(np, "exceptions", np).ComplexWarning
    odd = [str(w.message) for w in caught if issubclass(w.category, complex_warning)]
    assert not odd, odd[:5]
    # The corpus exercises both sides: calls that work and calls refused.
    assert counts["returned"] > 100 and counts["raised"] > 300, counts
    print(f"{CASES} cases: {counts}, 0 panics")


def run_corpus(rng, tmp_path, root, scenario, mesh, counts, panics):
    for case in range(CASES):
        for call in fuzz_case(rng, tmp_path, root, scenario, mesh):
            try:
                call()
                counts["returned"] += 1
            except StopIteration:  # a finished run, as an iterator ends
                counts["raised"] += 1
            except Exception as e:  # an ordinary, documented kind of error
                assert str(e), f"case {case}: {type(e).__name__} without a message"
                counts["raised"] += 1
            except BaseException as e:  # PanicException and the like
                if isinstance(e, (KeyboardInterrupt, SystemExit)):
                    raise
                panics.append(f"case {case}: {type(e).__name__}: {e}")
