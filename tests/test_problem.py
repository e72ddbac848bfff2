"""One problem built once, solved once and kept with its result
(``musclemetab.redundancy.problem``): the problem a result keeps gives the same samples as the
files, and it round-trips through ``problem.json`` (``redundancy.problem_file``). The problems
are small (one DOF, a 0.3 s window) and their geometry comes from the test run's cache."""

from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

WINDOW = (0.6, 0.9)
DOFS = ["ankle_angle_r"]


def _same_problem(a, b):
    """Every array, parameter and setting of two problems equal (to 1e-12 relative)."""
    assert (a.workflow, a.side, a.dofs, a.labels, a.excluded_muscles) == (b.workflow, b.side, b.dofs, b.labels,
                                                                           b.excluded_muscles)
    assert (a.goals, a.options, a.specs, a.emg, dict(a.emg_mapping)) == (b.goals, b.options, b.specs, b.emg,
                                                                         dict(b.emg_mapping))
    assert a.parameters.names == b.parameters.names
    from musclemetab.redundancy.parameters import PARAMETER_FIELDS

    for f in PARAMETER_FIELDS:
        np.testing.assert_allclose(getattr(a.parameters, f), getattr(b.parameters, f), rtol=1e-12, err_msg=f)
    for s, t in zip(a.trials, b.trials):
        assert s.geometry.muscles == t.geometry.muscles and s.geometry.dofs == t.geometry.dofs
        for x, y in ((s.geometry.lmt_m, t.geometry.lmt_m), (s.geometry.moment_arms_m, t.geometry.moment_arms_m),
                     (s.id_moments_Nm, t.id_moments_Nm), (s.id_time_s, t.id_time_s), (s.ik_time_s, t.ik_time_s)):
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=0)
        assert s.diagnosis.to_dict() == t.diagnosis.to_dict()


@pytest.mark.opensim
def test_problem_json_names_the_files_as_the_solve_record_does(example, geometry_cache, tmp_path):
    """``problem.json`` names each input file as the solve's record names it (``summary.json``
    ``inputs``, :func:`~musclemetab.io.source_path`): absolute, a link kept as
    the user named it (a data folder reached through a link), not the file it points to; the
    problem is read back through the link."""
    import json

    from musclemetab.redundancy.problem import TrialFiles, load_problem, read_problem
    from musclemetab.io import source_path

    data = tmp_path / "data"
    data.symlink_to(example.model.parent, target_is_directory=True)
    model, ik, idf = (data / p.name for p in (example.model, example.ik["normal"], example.id["normal"]))
    problem = load_problem(model, [TrialFiles(ik, idf)], window=WINDOW, dofs=DOFS, cache_dir=geometry_cache)
    problem.write(tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "problem.json").read_text())
    trial = doc["keywords"]["trials"][0]
    assert (doc["keywords"]["model"], trial["ik"], trial["id"]) == (str(model), str(ik), str(idf))
    assert str(source_path(idf)) == str(idf) != str(example.id["normal"].resolve())
    assert set(doc["sha256"]) == {str(model), str(ik), str(idf)}
    _same_problem(read_problem(tmp_path / "out", cache_dir=geometry_cache), problem)


@pytest.mark.opensim
def test_problem_json_round_trip(example, geometry_cache, tmp_path):
    """``problem.json`` rebuilds the problem (muscle parameters changed after the load
    included); a file changed or gone since, or a folder without ``problem.json`` (written
    before results kept their problem), gives ``None`` and a warning saying which and why."""
    from musclemetab.errors import MusclemetabWarning
    from musclemetab.redundancy.problem import TrialFiles, load_problem, read_problem

    idf = tmp_path / "id.sto"  # a copy to change and remove (the IK file's geometry is in the cache)
    shutil.copy(example.id["normal"], idf)
    problem = load_problem(example.model, [TrialFiles(example.ik["normal"], idf)], workflow="effort-cal",
                           window=WINDOW, dofs=DOFS, cache_dir=geometry_cache)
    scaled = problem.parameters.replace(tendon_slack_length_m={problem.parameters.names[0]: 0.3})
    problem = problem.with_parameters(scaled)
    problem.write(tmp_path / "out")
    again = read_problem(tmp_path / "out", cache_dir=geometry_cache)
    _same_problem(again, problem)
    assert again.parameters.tendon_slack_length_m[0] == 0.3
    idf.write_text(idf.read_text() + "\n")
    with pytest.warns(MusclemetabWarning, match=r"id.sto is changed since the solve"):
        assert read_problem(tmp_path / "out") is None
    idf.unlink()
    with pytest.warns(MusclemetabWarning, match=r"id.sto is gone since the solve"):
        assert read_problem(tmp_path / "out") is None
    (tmp_path / "old").mkdir()
    with pytest.warns(MusclemetabWarning, match=r"no problem.json \(written before"):
        assert read_problem(tmp_path / "old") is None


@pytest.mark.opensim
def test_sample_from_the_kept_problem_equals_the_sample_from_files(example, geometry_cache, tmp_path):
    """An uncertainty sample solved from ``nominal.problem`` (``problem.with_parameters``, as
    ``uncertainty_coverage.solve_draw`` does) is the sample solved from the files
    (``solve_files(..., parameter_transform=...)``): objective and arrays to 1e-9 relative."""
    from musclemetab.redundancy.problem import solve
    from musclemetab.redundancy.run import solve_files
    from musclemetab.uncertainty import default_priors, draw

    files = (example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nominal = solve_files(*files, window=WINDOW, dofs=DOFS, cache_dir=geometry_cache)
        d = draw(default_priors(), nominal.muscles, 1, 7)
        from_files = solve_files(*files, window=WINDOW, dofs=DOFS, cache_dir=geometry_cache,
                                 parameter_transform=d.parameters)
        kept = nominal.problem
        from_problem = next(iter(solve(kept.with_parameters(d.parameters(kept.parameters))).solutions.values()))
    assert from_files.success and from_problem.success
    assert from_problem.objective == pytest.approx(from_files.objective, rel=1e-9)
    for name in from_files.ARRAYS:
        np.testing.assert_allclose(getattr(from_problem, name), getattr(from_files, name), rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    _same_problem(from_problem.problem, from_files.problem)
    from musclemetab.errors import OptionError

    with pytest.raises(OptionError, match="result of a single-trial solve has no parameters.json"):
        solve(kept).write(tmp_path)  # its solution is what is written


@pytest.mark.opensim
def test_sensitivity_from_the_kept_problem_equals_the_one_from_files(example, geometry_cache):
    """The problem the sensitivities start from (``problem_of_solution``) taken from
    ``solution.problem`` is the one rebuilt from the files its ``summary.json`` names (the same
    solution without its problem): mesh inputs and a sensitivity (lTs of soleus, UM10) to 1e-9
    relative."""
    from dataclasses import replace

    from musclemetab.redundancy.run import solve_files
    from musclemetab.redundancy.sensitivity import problem_of_solution, trial_sensitivity

    solution = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-gen", window=WINDOW,
                           dofs=DOFS, cache_dir=geometry_cache)
    assert solution.problem is not None
    kept, files = problem_of_solution(solution), problem_of_solution(replace(solution, problem=None))
    assert kept.inputs.muscles == files.inputs.muscles and kept.goals == files.goals
    for name in ("mesh_time_s", "lmt_m", "moment_arms_m", "moments_Nm", "lmt_velocity_frames_m_per_s"):
        np.testing.assert_allclose(getattr(kept.inputs, name), getattr(files.inputs, name), rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sens = [trial_sensitivity(p.solution, p.inputs, p.params, p.goals, body_mass_kg=example.body_mass_kg,
                                  height_m=example.height_m, models="UM10", parameters=[("lTs", "soleus_r")],
                                  trial="normal") for p in (kept, files)]
    a, b = (s.table().sort_values(["rate", "parameter", "muscle"]).reset_index(drop=True) for s in sens)
    assert abs(a.d_rate_d_log_p).max() > 0.01
    np.testing.assert_allclose(a.d_rate_d_log_p, b.d_rate_d_log_p, rtol=1e-9, atol=1e-12)
