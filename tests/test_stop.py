"""Where the solver stops: the optimum by default, the study's stop by name (docs/solver.md).

The rates of the default stop are compared with those of a solve of the same problem at IPOPT
tolerance 1e-10 with the monotone barrier (another path of the solver to the same optimum); the
study's stop with the objective the package stored before the stop had a name
(``tests/data/pre_core_results.json``) and the study's IPOPT log (docs/solver.md).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

TEST_DATA = Path(__file__).resolve().parent / "data"
#: 0.3 s of the normal trial (inside the ID file; the cycle starts at 0.53 s), a window no other test
#: solves (test_cli_flow's two legs watch their own solves' progress on 0.6-0.9 s)
WINDOW = (0.65, 0.95)


@pytest.fixture(scope="module")
def short_solves(example, geometry_cache):
    """EFFORT-GEN on 0.3 s of the normal trial with the default stop, the study's stop and at
    tolerance 1e-10 (monotone), each solved once (``tests/solve_memo.py``)."""
    from musclemetab.redundancy import SolverOptions, solve_files

    files = (example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, options in (("default", None), ("authors", SolverOptions(stop="authors")),
                              ("tol 1e-10", SolverOptions(stop="authors", tol=1e-10))):
            out[name] = solve_files(*files, window=WINDOW, cache_dir=geometry_cache, options=options)
    return out


def _rates(example, solution):
    from musclemetab.metabolics.solution import metabolics_from_solution

    met = metabolics_from_solution(solution, example.body_mass_kg, example.height_m, models="all", trim=(0, 0))
    return ({m: met.whole_body[m].mean_W_per_kg for m in met.models},
            {m: np.asarray(met.rates[m].total_without_basal()).mean(axis=1) for m in met.models})


@pytest.mark.opensim
def test_default_rates_are_those_of_the_optimum(example, short_solves):
    """Every model's whole-body rate of the default solve within 1 % of the rate at tolerance
    1e-10, and every muscle above 1 % of the leg within 2 %; the study's stop is far from it."""
    default, reference, authors = (short_solves[k] for k in ("default", "tol 1e-10", "authors"))
    assert default.success and reference.success and authors.success
    assert default.record.solver_options["stop"] == "optimum" and default.record.solver_options["tol"] == 1e-8
    wb, per = _rates(example, default)
    wb_ref, per_ref = _rates(example, reference)
    wb_authors, _ = _rates(example, authors)
    for m in wb_ref:
        assert wb[m] == pytest.approx(wb_ref[m], rel=0.01), m
        big = per_ref[m] > 0.01 * per_ref[m].sum()
        np.testing.assert_allclose(per[m][big], per_ref[m][big], rtol=0.02, err_msg=m)
    # the study's stop: the UM10 rate stays well above the optimum's on this window
    assert wb_authors["UM10"] > 1.02 * wb_ref["UM10"]
    assert default.objective == pytest.approx(reference.objective, rel=1e-6)
    assert authors.objective > reference.objective * (1 + 1e-4)


@pytest.mark.opensim
def test_convergence_record_and_flag(short_solves, tmp_path):
    """The record says how converged the rates are: the study's stop is flagged, the default is
    not; the record round-trips through the solution folder."""
    from musclemetab.redundancy import Solution

    default, authors = short_solves["default"], short_solves["authors"]
    conv, conv_a = default.record.convergence, authors.record.convergence
    assert conv["stop"] == "optimum" and conv_a["stop"] == "authors" and conv_a["tolerance"] == 1e-6
    # a_mu = sqrt(mu N M / w) worked by hand from the recorded barrier parameter
    n, m = len(default.time_s) - 1, len(default.muscles)
    assert conv["off_level"] == pytest.approx(np.sqrt(conv["final_barrier_parameter"] * n * m), rel=1e-12)
    assert conv["final_barrier_parameter"] < 1e-9 < conv_a["final_barrier_parameter"]
    assert conv["max_rate_residue"] < 0.01 < conv_a["max_rate_residue"]
    assert "unconverged_rates" in [f.code for f in authors.record.flags]
    assert "unconverged_rates" not in [f.code for f in default.record.flags]
    default.write(tmp_path / "sol")
    again = Solution.load(tmp_path / "sol")
    assert again.record.convergence == json.loads(json.dumps(conv.to_dict()))


@pytest.mark.opensim
def test_authors_stop_reproduces_the_stored_objective(example, geometry_cache):
    """``--stop authors``: the study's settings give the objective stored before the stop had a
    name (normal EFFORT-GEN, 2.316791e-2) to 1e-6, and the study's log (2.3170e-2) to 0.01 %."""
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    stored = json.loads((TEST_DATA / "pre_core_results.json").read_text())["effort"]["normal/effort-gen"]
    out = Path(geometry_cache).parent / "stop_authors_normal_gen"
    argv = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--workflow", "effort-gen", "--stop", "authors", "--no-progress",
            "--cache-dir", str(geometry_cache), "--out", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(argv) == 0
    sol = Solution.load(out)
    assert sol.record.solver_options["stop"] == "authors"
    assert sol.objective == pytest.approx(stored["objective"], rel=1e-6)
    assert sol.objective == pytest.approx(2.3170e-2, rel=1e-4)


def test_stop_names_are_checked():
    from musclemetab.errors import OptionError
    from musclemetab.redundancy import SolverOptions

    with pytest.raises(OptionError, match="stop"):
        SolverOptions(stop="loose")
    assert SolverOptions().tolerance == 1e-8
    assert SolverOptions(stop="authors").tolerance == 1e-6
    assert SolverOptions(stop="authors", tol=1e-9).tolerance == 1e-9


def test_controls_a_hair_outside_their_bounds_reach_the_models_inside(example):
    """A solution whose activations and excitations lie 1e-8 outside [0, 1] (IPOPT's relaxed
    bounds) gives the rates of the same solution clipped (UM10's A^0.6 would be NaN); 1e-3
    outside is refused, naming the muscle."""
    from musclemetab.errors import DataMismatchError
    from musclemetab.metabolics.solution import SolutionStates, metabolics_from_solution

    data = np.load(TEST_DATA / "example_normal_effort_gen_metabolic_inputs.npz")
    muscles = tuple(f"m{i}" for i in range(data["excitation"].shape[0]))
    names = ("excitation", "activation", "normalized_fiber_length", "normalized_fiber_velocity",
             "active_force_length_multiplier", "force_velocity_multiplier", "passive_fiber_force_N")
    params = {m: {"max_isometric_force_N": float(f), "optimal_fiber_length_m": float(lo), "max_contraction_velocity": float(v)}
              for m, f, lo, v in zip(muscles, data["max_isometric_force_N"], data["optimal_fiber_length_m"],
                                     data["max_contraction_velocity"])}

    def rates(shift_low, shift_high):
        states = {k: np.array(data[k], dtype=float) for k in names}
        for k in ("excitation", "activation"):
            states[k][:, 0] = -shift_low  # a node of every muscle below zero
            states[k][0, 1] = 1 + shift_high  # and one above one
        sol = SolutionStates(time_s=np.array(data["time_s"]), muscles=muscles, states=states, parameters=params)
        met = metabolics_from_solution(sol, 72.6, None, models="UM10,BH04", trim=(0, 0),
                                       muscle_masses_kg=dict(zip(muscles, data["muscle_mass_kg"])),
                                       slow_twitch_fractions=dict(zip(muscles, data["slow_twitch_fraction"])))
        return {m: met.whole_body[m].mean_W_per_kg for m in met.models}

    outside, clipped = rates(1e-8, 1e-8), rates(0.0, 0.0)
    for m in clipped:
        assert np.isfinite(outside[m]) and outside[m] == pytest.approx(clipped[m], rel=1e-12)
    with pytest.raises(DataMismatchError, match="m0"):
        rates(1e-3, 0.0)
