"""Figures and the HTML report of a study folder.

The study folders are synthetic: results and time-series tables built here with the study
runner's layout, and solver solutions built from synthetic arrays in the solver's format
(:class:`~musclemetab.redundancy.Solution`, written with its own writer).
"""

from __future__ import annotations

import json
import math
import os
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import InputFileError, MissingColumnError, OptionError, UnknownMuscleError
from musclemetab.redundancy import MuscleTendonParameters, Solution
from musclemetab.redundancy.record import RunRecord, SolveRecord
from musclemetab.report import (
    FIGURE_NAMES,
    GROUPS,
    estimated_vs_measured,
    excitations_and_fiber_lengths,
    group_rates_over_cycle,
    group_shares,
    phase_shares,
    save_figure,
    whole_body_over_cycle,
    write_report,
)
from musclemetab.report.figures import model_colour, preferred_trial, trial_order, workflow_colour

MUSCLES = ("soleus_r", "gasmed_r", "tibant_r", "vaslat_r", "recfem_r", "glmax2_r", "addlong_r")
TRIALS = {"slow": 0.75, "normal": 1.25, "fast": 1.75}
WORKFLOWS = ("effort-gen", "effort-ten")
MODELS = ("UM10", "BH04", "HO06")
ORDERED = ("BH04", "HO06", "UM10")  # figures order models as the paper's Table 2
SUBJECTS = {"s1": (70.0, 1.75), "s2": (62.0, 1.66), "s3": (81.0, 1.82)}
CYCLE = (0.62, 1.29, 1.70)  # start, toe-off, end (s)
TOE_OFF_PCT = 100.0 * (CYCLE[1] - CYCLE[0]) / (CYCLE[2] - CYCLE[0])


# ------------------------------------------------------------------------ synthetic data
#: iterations recorded in each workflow's synthetic run record
ITERATIONS = {"effort-gen": 31, "effort-ten": 47}


def make_solution(workflow: str, muscles=MUSCLES) -> Solution:
    """A solution on the mesh of the cycle plus 5 padding nodes at both ends."""
    h = 0.01
    t = np.arange(CYCLE[0] - 5 * h, CYCLE[2] + 5 * h + 1e-9, h)
    n, m = t.size, len(muscles)
    phase = 2 * np.pi * (t[:, None] - CYCLE[0]) / (CYCLE[2] - CYCLE[0]) + np.arange(m)[None, :]
    shift = 0.1 if workflow == "effort-ten" else 0.0
    e = np.clip(0.3 + 0.25 * np.sin(phase), 0.01, 1.0)
    a = np.clip(0.3 + 0.25 * np.sin(phase - 0.3), 0.01, 1.0)
    lm = 0.95 + shift + 0.15 * np.cos(phase)
    params = MuscleTendonParameters(
        names=muscles, max_isometric_force_N=np.full(m, 2000.0), optimal_fiber_length_m=np.full(m, 0.06),
        tendon_slack_length_m=np.full(m, 0.25), pennation_angle_at_optimal_rad=np.full(m, 0.1),
        max_contraction_velocity=np.full(m, 10.0), tendon_stiffness=np.full(m, 35.0),
        passive_kpe=np.full(m, 4.0), passive_s0=np.full(m, 0.6), passive_sm=np.full(m, 0.6),
    )
    zeros = np.zeros((n, m))
    return Solution(
        time_s=t, muscles=tuple(muscles), dofs=("ankle_angle_r",), excitation=e, activation=a, lm_norm=lm,
        fiber_velocity_lmo_per_s=zeros, tendon_force_N=zeros, active_fiber_force_N=zeros, passive_fiber_force_N=zeros,
        active_force_length_multiplier=np.ones((n, m)), force_velocity_multiplier=np.ones((n, m)),
        reserve_Nm=np.zeros((n, 1)), parameters=params,
        record=SolveRecord.from_dict({**RunRecord(status="Solve_Succeeded", success=True, iterations=ITERATIONS[workflow], solve_time_s=1.25,
                             max_constraint_violation=3e-7).to_dict(),
                 "workflow": {"name": workflow}, "side": "r", "max_moment_residual_Nm": 2e-6}),
    )


def _bump(pct, centre, width, height):
    return height * np.exp(-0.5 * ((pct - centre) / width) ** 2)


WORKFLOW_SCALE = {"effort-gen": 1.2, "effort-cal": 1.1, "emg-ten": 1.5}


def timeseries_arrays(speed: float, models=None, workflow="effort-ten") -> tuple[np.ndarray, dict]:
    """Group rates (W) over the cycle: early-stance, pre-swing and swing peaks that change with speed;
    ``(cycle %, {model: {series: rates}})``, the series ``group/<G>`` and ``leg_muscles`` (their sum)."""
    models = MODELS if models is None else models
    pct = np.linspace(0.0, 100.0, 51)
    out = {}
    for k, model in enumerate(models):
        scale = (1.0 + 0.15 * k) * WORKFLOW_SCALE.get(workflow, 1.0)
        groups = {}
        for i, g in enumerate(GROUPS):
            groups[g] = scale * (
                (0.5 + speed) * _bump(pct, 10 + 3 * i, 6, 20 + 2 * i)
                + speed**2 * _bump(pct, 55, 5, 30 if g in ("PF", "HAB") else 5)
                + _bump(pct, 75, 6, 18 if g in ("HF", "HAD", "KE") else 2) + 1.0
            )
        out[model] = {**{f"group/{g}": v for g, v in groups.items()}, "leg_muscles": sum(groups.values())}
    return pct, out


def timeseries_table(pct, series: dict) -> pd.DataFrame:
    """The time-series table (``timeseries.csv``) of :func:`timeseries_arrays`."""
    time = CYCLE[0] + pct / 100 * (CYCLE[2] - CYCLE[0])
    pairs = [(model, name) for model, by_name in series.items() for name in by_name]
    n = pct.size
    return pd.DataFrame({
        "time_s": np.tile(time, len(pairs)), "cycle_pct": np.tile(pct, len(pairs)),
        "model": np.repeat([m for m, _ in pairs], n), "series": np.repeat([s for _, s in pairs], n),
        "value_W": np.concatenate([series[m][s] for m, s in pairs]),
    })


def make_timeseries(speed: float, models=None, workflow="effort-ten") -> pd.DataFrame:
    """:func:`timeseries_arrays` as the time-series table."""
    return timeseries_table(*timeseries_arrays(speed, models, workflow))


def _integral(pct, v, lo=0.0, hi=100.0):
    m = (pct >= lo) & (pct <= hi)
    return float(np.trapezoid(v[m], pct[m]))


#: the synthetic per-muscle split of the leg's rate (sums to 1)
MUSCLE_PARTS = {"soleus_r": 0.3, "gasmed_r": 0.25, "vaslat_r": 0.2, "psoas_r": 0.15, "tibant_r": 0.1}


def write_metabolics_sto(folder: Path, speed: float) -> dict:
    """A unit's ``metabolics.sto``: each muscle's total and basal rate (W) at the cycle's nodes;
    returns the columns written."""
    from musclemetab.io.storage import write_storage

    t = np.round(np.linspace(CYCLE[0], CYCLE[2], 41), 6)
    phase = (t - CYCLE[0]) / (CYCLE[2] - CYCLE[0])
    cols = {}
    for k, model in enumerate(MODELS):
        for j, mu in enumerate(MUSCLE_PARTS):
            cols[f"{model}/{mu}/total"] = (k + 1) * speed * (1 + j + np.sin(np.pi * (phase + 0.1 * j)) ** 2)
            cols[f"{model}/{mu}/basal"] = np.full(t.size, 0.1 * (j + 1))
    write_storage(folder / "metabolics.sto", pd.DataFrame(cols, index=pd.Index(t, name="time")))
    return cols


def make_study(root: Path, *, measured=True, trials=None, solutions=True, failed=()) -> Path:
    """A study folder with the runner's layout; ``failed``: (subject, trial, workflow) units that failed."""
    trials = TRIALS if trials is None else trials
    root.mkdir(parents=True, exist_ok=True)
    sol = {w: make_solution(w) for w in WORKFLOWS} if solutions else {}
    rows, failures, muscles = [], [], []
    rng = np.random.default_rng(1)
    for si, (subject, (mass, height)) in enumerate(SUBJECTS.items()):
        for trial, speed in trials.items():
            sp = speed * (1 + 0.04 * si)
            meas = 2.2 + 1.8 * sp + 0.3 * si + 0.05 * rng.standard_normal()
            for workflow in WORKFLOWS:
                rel = Path("units") / subject / trial / workflow
                folder = root / rel
                folder.mkdir(parents=True, exist_ok=True)
                if (subject, trial, workflow) in failed:
                    (folder / "unit.json").write_text(json.dumps(
                        {"status": "failed", "subject": subject, "trial": trial, "workflow": workflow,
                         "error": "solver did not converge <maximum iterations>"}))
                    (folder / "summary.json").write_text(json.dumps(RunRecord(
                        status="Maximum_Iterations_Exceeded", success=False, iterations=3000).to_dict()))
                    failures.append({"subject": subject, "trial": trial, "workflow": workflow,
                                     "reason": "solver did not converge <maximum iterations>"})
                    continue
                pct, series = timeseries_arrays(sp, workflow=workflow)
                timeseries_table(pct, series).to_csv(folder / "timeseries.csv", index=False)
                write_metabolics_sto(folder, sp)
                if solutions:
                    sol[workflow].write(folder)
                (folder / "unit.json").write_text(json.dumps({
                    "status": "ok", "subject": subject, "trial": trial, "workflow": workflow, "speed_m_per_s": sp,
                    "cycle": {"start_s": CYCLE[0], "toe_off_s": CYCLE[1], "end_s": CYCLE[2]}, "error": None,
                    "times": {},
                }))
                for model in MODELS:
                    wb = series[model]["leg_muscles"]
                    total = _integral(pct, wb)
                    stance = 100 * _integral(pct, wb, 0, TOE_OFF_PCT) / total
                    mean_w = total / 100.0
                    row = {
                        "subject": subject, "trial": trial, "workflow": workflow, "model": model,
                        "speed_m_per_s": sp, "status": "ok",
                        "whole_body_W_per_kg": 2 * mean_w / mass + 1.2, "whole_body_no_basal_W_per_kg": 2 * mean_w / mass,
                        "gross_cost_of_transport_J_per_kg_per_m": (2 * mean_w / mass + 1.2) / sp,
                        "stance_energy_share_pct": stance, "swing_energy_share_pct": 100 - stance,
                        "stance_energy_share_with_basal_pct": stance - 2, "swing_energy_share_with_basal_pct": 102 - stance,
                    }
                    for g in GROUPS:
                        gv = series[model][f"group/{g}"]
                        row[f"share_{g}_pct"] = 100 * _integral(pct, gv) / total
                    row.update(toe_off_pct=TOE_OFF_PCT, measured_W_per_kg=meas if measured else math.nan,
                               unit_dir=str(rel))
                    rows.append(row)
                    # a per-muscle table whose muscles add up to the leg: fixed proportions of mean_w
                    for k, (mu, part) in enumerate(MUSCLE_PARTS.items()):
                        muscles.append({"subject": subject, "trial": trial, "workflow": workflow, "model": model,
                                        "muscle": mu, "side": "r", "muscle_W": part * mean_w,
                                        "muscle_W_per_kg": part * mean_w / mass, "rank": k + 1})
    pd.DataFrame(rows).to_csv(root / "results.csv", index=False)
    pd.DataFrame(muscles).to_csv(root / "per_muscle.csv", index=False)
    pd.DataFrame(failures, columns=["subject", "trial", "workflow", "reason"]).to_csv(root / "failures.csv", index=False)
    settings = {
        "name": "speeds <synthetic> & co",
        "workflows": list(WORKFLOWS),
        "models": list(MODELS),
        "basal": "body",
        "subjects": {s: {"body_mass_kg": m, "height_m": h, "model": f"data/{s}.osim", "trials": list(trials)}
                     for s, (m, h) in SUBJECTS.items()},
        "software": {"musclemetab": "0.1.0", "numpy": "2.0.0", "opensim": "4.6-study", "casadi": "3.6.0"},
    }
    (root / "study.json").write_text(json.dumps(settings, indent=2))
    return root


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    return make_study(tmp_path_factory.mktemp("study"))


@pytest.fixture(scope="module")
def results(study) -> pd.DataFrame:
    return pd.read_csv(study / "results.csv")


# ------------------------------------------------------------------------------- helpers
def _lines(ax, prefix):
    return [ln for ln in ax.get_lines() if (ln.get_gid() or "").startswith(prefix)]


def _bars(ax, gid):
    """``(x, y, width, height)`` of each bar named ``gid`` (its collection's polygons), in data units."""
    out = []
    for c in ax.collections:
        if c.get_gid() == gid:
            for path in c.get_paths():
                v = path.vertices
                lo, hi = v.min(axis=0), v.max(axis=0)
                out.append((lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]))
    return out


def _visible_axes(fig):
    return [ax for ax in fig.axes if ax.get_visible()]


#: The functions drawing the report's figures (module, names): each turns the data the
#: report's plan (:mod:`musclemetab.report.plan`) read and checked into a matplotlib figure.
DRAWING_FUNCTIONS = (
    ("musclemetab.report.figures", ("excitations_and_fiber_lengths", "estimated_vs_measured", "group_rates_over_cycle",
                                    "muscle_heat_map", "whole_body_over_cycle", "phase_shares", "phase_pies",
                                    "group_shares", "rates_against_speed", "per_muscle_ranked", "figure2_compact")),
    ("musclemetab.report.spread_figure", ("spread_figure",)),
)


def small_figures(monkeypatch, tmp_path, keep=()):
    """Every drawing function but those named in ``keep`` draws a small figure holding its name
    instead (one line of text, saved in about 10 ms where the report's figures take a second
    each), for the tests of the report's mechanics (files, rebuild key, page order,
    drawing processes). The plan still reads every unit file a figure needs and still
    raises the notes of missing files and single speeds. The package's cache is the test's own
    (``tmp_path/cache``), so that no small figure stands for the real Figure 2 in the cache and
    no drawing time of one is kept for the real figures."""
    import importlib

    def small(name):
        def draw(*args, **kwargs):
            from matplotlib.figure import Figure

            fig = Figure(figsize=(2.0, 0.3))
            fig.text(0.02, 0.3, name, fontsize=6)
            return fig

        return draw

    for module, names in DRAWING_FUNCTIONS:
        for name in names:
            if name not in keep:
                monkeypatch.setattr(importlib.import_module(module), name, small(name))
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path / "cache"))


class _Parser(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags, self.stack, self.imgs, self.tables, self.ids = [], [], [], 0, set()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "img":
            self.imgs.append(a)
        elif tag == "table":
            self.tables += 1
        if tag not in ("img", "meta", "br", "hr", "link", "input"):
            self.stack.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, f"unbalanced </{tag}> (open: {self.stack[-3:]})"
        self.stack.pop()


def _parse(text):
    p = _Parser()
    p.feed(text)
    p.close()
    assert not p.stack, f"unclosed tags {p.stack}"
    return p


# ----------------------------------------------------------------------------- figure 1
def test_excitations_and_fiber_lengths():
    sols = {w: make_solution(w) for w in WORKFLOWS}
    cycles = {w: CYCLE for w in WORKFLOWS}
    fig = excitations_and_fiber_lengths(sols, cycles)
    axes = _visible_axes(fig)
    # default muscles present: soleus, gasmed, tibant, vaslat, recfem, glmax2 -> 6 muscles x 2 panels
    assert len(axes) == 12
    titles = [ax.get_title() for ax in axes if ax.get_title()]
    # each muscle named as everywhere in the report: the anatomical muscle with the model's name
    assert titles == ["soleus (soleus_r)", "gastrocnemius medialis (gasmed_r)", "tibialis anterior (tibant_r)",
                      "vastus lateralis (vaslat_r)", "rectus femoris (recfem_r)", "gluteus maximus (glmax2_r)"]
    for ax in axes:
        data = _lines(ax, "workflow:")
        assert len(data) == len(WORKFLOWS)
        assert {ln.get_color() for ln in data} == {workflow_colour(w) for w in WORKFLOWS}
        to = _lines(ax, "toe-off")
        assert len(to) == 1 and np.allclose(to[0].get_xdata(), TOE_OFF_PCT)
        for ln in data:  # padding nodes dropped, the cycle in %
            x = np.asarray(ln.get_xdata())
            assert x.min() == pytest.approx(0.0, abs=1e-9) and x.max() == pytest.approx(100.0, abs=1e-9)
    # fiber-length panels: plateau band and descending-limb line
    fl = [ax for ax in axes if "fiber length" in ax.get_ylabel() or _lines(ax, "descending-limb")]
    assert len(fl) == 6
    for ax in fl:
        assert np.allclose(_lines(ax, "descending-limb")[0].get_ydata(), 1.05)
        band = [p for p in ax.patches if p.get_gid() == "plateau"]
        assert len(band) == 1
        display = band[0].get_transform().transform(band[0].get_path().vertices)
        y = ax.transData.inverted().transform(display)[:, 1]
        assert (y.min(), y.max()) == pytest.approx((0.75, 1.05))
    # values: the excitation line of soleus equals the solution's cycle nodes
    ax_e = axes[0]
    ln = _lines(ax_e, "workflow:effort-gen")[0]
    t = sols["effort-gen"].time_s
    keep = (t >= CYCLE[0] - 1e-9) & (t <= CYCLE[2] + 1e-9)
    assert np.allclose(ln.get_ydata(), sols["effort-gen"].excitation[keep, 0])


def test_excitations_muscle_choice_and_errors():
    sols = {"effort-gen": make_solution("effort-gen")}
    fig = excitations_and_fiber_lengths(sols, {"effort-gen": CYCLE}, muscles=["soleus", "addlong_r"])
    assert len(_visible_axes(fig)) == 4
    with pytest.raises(UnknownMuscleError, match="psoas"):
        excitations_and_fiber_lengths(sols, {"effort-gen": CYCLE}, muscles=["psoas"])
    with pytest.raises(OptionError, match="gait cycle"):
        excitations_and_fiber_lengths(sols, {})
    with pytest.raises(OptionError, match="increasing"):
        excitations_and_fiber_lengths(sols, {"effort-gen": (1.0, 0.9, 2.0)})
    with pytest.raises(OptionError):
        excitations_and_fiber_lengths({}, {})


# ----------------------------------------------------------------------------- figure 2
def _rmcorr_lstsq(x, y, subject):
    """Common slope of the ANCOVA with one dummy per subject, by least squares."""
    subjects = sorted(set(subject))
    X = np.column_stack([x] + [(np.asarray(subject) == s).astype(float) for s in subjects])
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    return coef[0], dict(zip(subjects, coef[1:]))


def test_estimated_vs_measured(results):
    fig = estimated_vs_measured(results)
    axes = _visible_axes(fig)
    assert [ax.get_title() for ax in axes] == list(ORDERED)
    for ax, model in zip(axes, ORDERED):
        assert len(_lines(ax, "identity")) == 1
        for w in WORKFLOWS:
            lines = _lines(ax, f"rmcorr:{w}:")
            assert len(lines) == len(SUBJECTS)  # one parallel segment per subject
            d = results[(results["model"] == model) & (results["workflow"] == w)]
            slope, intercepts = _rmcorr_lstsq(d["measured_W_per_kg"].to_numpy(), d["whole_body_W_per_kg"].to_numpy(),
                                              d["subject"].to_numpy())
            for ln in lines:
                x, y = np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float)
                assert (y[1] - y[0]) / (x[1] - x[0]) == pytest.approx(slope, rel=1e-9)
                s = ln.get_gid().split(":")[2]
                assert y[0] - slope * x[0] == pytest.approx(intercepts[s], rel=1e-9)
                assert ln.get_color() == workflow_colour(w)
        # points: every subject x trial x workflow
        n_points = sum(len(c.get_offsets()) for c in ax.collections)
        assert n_points == len(SUBJECTS) * len(TRIALS) * len(WORKFLOWS)
        assert ax.get_xlabel() == "measured (W/kg)" and ax.get_ylabel() == "estimated (W/kg)"


def test_estimated_vs_measured_without_measurements(results):
    with pytest.raises(OptionError, match="measured"):
        estimated_vs_measured(results.assign(measured_W_per_kg=np.nan))


def test_estimated_vs_measured_one_subject(results):
    fig = estimated_vs_measured(results[results["subject"] == "s1"])
    for ax in _visible_axes(fig):
        assert _lines(ax, "rmcorr:") == [] and len(_lines(ax, "identity")) == 1
        assert sum(len(c.get_offsets()) for c in ax.collections) == len(TRIALS) * len(WORKFLOWS)
    assert "Lines not drawn: " in fig.get_suptitle() and "subject" in fig.get_suptitle()


# ----------------------------------------------------------------------------- figures 3, 4
def test_group_rates_over_cycle():
    """Small multiples: one panel per group (shared axes), one line per model, each line the
    table's series of that group and model times the scale."""
    ts = make_timeseries(1.25)
    fig = group_rates_over_cycle(ts, 61.3, ["BH04", "UM10"], scale=0.5, unit="W/kg")
    axes = _visible_axes(fig)
    assert [ax.get_title().split(":")[0] for ax in axes] == list(GROUPS)
    for ax, g in zip(axes, GROUPS):
        assert [ln.get_gid() for ln in _lines(ax, "model:")] == ["model:BH04", "model:UM10"]
        for model in ("BH04", "UM10"):
            ln = _lines(ax, f"model:{model}")[0]
            ref = ts[(ts["model"] == model) & (ts["series"] == f"group/{g}")]
            assert np.allclose(ln.get_ydata(), 0.5 * ref["value_W"])
            assert ln.get_color().lower() == model_colour(model).lower()
        assert np.allclose(_lines(ax, "toe-off")[0].get_xdata(), 61.3)
        assert ax.get_shared_y_axes().joined(ax, axes[0])
    assert axes[0].get_ylabel() == "rate (W/kg)"
    with pytest.raises(OptionError, match="LW07"):
        group_rates_over_cycle(ts, 61.3, ["LW07"])
    with pytest.raises(OptionError, match="toe-off"):
        group_rates_over_cycle(ts, 120.0)
    with pytest.raises(OptionError, match="group"):
        group_rates_over_cycle(ts[ts["series"] == "leg_muscles"], 60.0)


def test_whole_body_over_cycle():
    tables = {t: make_timeseries(s) for t, s in TRIALS.items()}
    fig = whole_body_over_cycle(tables, TRIALS, toe_off_pct={t: 60.0 + i for i, t in enumerate(TRIALS)})
    axes = _visible_axes(fig)
    assert [ax.get_title() for ax in axes] == list(ORDERED)
    for ax in axes:
        lines = _lines(ax, "trial:")
        assert [ln.get_gid() for ln in lines] == ["trial:slow", "trial:normal", "trial:fast"]  # by speed
        assert len({ln.get_color() for ln in lines}) == 3
        assert sorted(np.asarray(ln.get_xdata())[0] for ln in _lines(ax, "toe-off")) == [60.0, 61.0, 62.0]
        peaks = [np.max(ln.get_ydata()) for ln in lines]
        assert peaks == sorted(peaks)  # synthetic rates grow with speed
    with pytest.raises(OptionError, match="speed"):
        whole_body_over_cycle(tables, {"slow": 0.75})


# ----------------------------------------------------------------------------- figures 5, 6
def test_phase_shares(results):
    fig = phase_shares(results)
    ax_b, ax_s = fig.axes
    # bars: one stance and one swing bar per model and workflow, stacking to 100 %
    for w in WORKFLOWS:
        st = [p for p in ax_b.patches if p.get_gid() == f"stance:{w}"]
        sw = [p for p in ax_b.patches if p.get_gid() == f"swing:{w}"]
        assert len(st) == len(sw) == len(ORDERED)
        for a, b in zip(st, sw):
            assert a.get_height() + b.get_height() == pytest.approx(100.0)
            assert b.get_y() == pytest.approx(a.get_height())
        d = results[(results["trial"] == "normal") & (results["workflow"] == w)]
        for a, m in zip(st, ORDERED):
            assert a.get_height() == pytest.approx(d[d["model"] == m]["stance_energy_share_pct"].mean())
    assert [t.get_text() for t in ax_b.get_xticklabels()] == list(ORDERED)
    # lines: one per model and subject, through the subject's trials of the main workflow (effort-ten)
    lines = _lines(ax_s, "model:")
    assert [ln.get_gid() for ln in lines] == [f"model:{m}:{s}" for m in ORDERED for s in SUBJECTS]
    assert [ln.get_color() for ln in lines] == [model_colour(m) for m in ORDERED for s in SUBJECTS]
    d = results[(results["workflow"] == "effort-ten") & (results["model"] == "BH04")]
    for s in SUBJECTS:
        ds = d[d["subject"] == s].set_index("trial").loc[["slow", "normal", "fast"]]
        ln = _lines(ax_s, f"model:BH04:{s}")[0]
        assert np.allclose(ln.get_xdata(), ds["speed_m_per_s"]) and np.allclose(ln.get_ydata(), ds["swing_energy_share_pct"])
    assert ax_s.get_xlabel() == "walking speed (m/s)"
    assert "%/(m/s)" in _lines(ax_s, "model:BH04")[0].get_label()


def test_phase_shares_one_speed(results):
    # one speed: no trend, no speed panel (it would be a vertical stripe at one speed); the
    # bars' panel says which trial it shows, not "the preferred speed"
    fig = phase_shares(results[results["trial"] == "fast"])
    (ax_b,) = fig.axes
    assert "of trial fast" in ax_b.get_title() and "preferred" not in ax_b.get_title()
    assert fig.shown["speeds"] == 1 and fig.shown["sd"]  # three subjects: SD drawn
    with pytest.raises(OptionError, match="trial 'normal'"):
        phase_shares(results[results["trial"] == "fast"], trial="normal")


def test_group_shares(results):
    fig = group_shares(results)
    axes = _visible_axes(fig)
    assert len(axes) == len(WORKFLOWS) * len(MODELS)
    assert [ax.get_title() for ax in axes[:len(ORDERED)]] == list(ORDERED)
    ax = axes[len(ORDERED) - 1]  # first row: effort-gen; last column: UM10
    pf = _bars(ax, "group:PF")
    assert len(pf) == len(TRIALS)
    d = results[(results["workflow"] == "effort-gen") & (results["model"] == "UM10")]
    exp = d.groupby("trial")["share_PF_pct"].mean().loc[["slow", "normal", "fast"]]
    assert np.allclose([h for _, _, _, h in sorted(pf)], exp)  # by x: slow, normal, fast
    from matplotlib.colors import to_rgb

    from musclemetab.report.figures import group_colour

    coll = next(c for c in ax.collections if c.get_gid() == "group:PF")
    assert np.allclose(coll.get_facecolor()[:, :3], to_rgb(group_colour("PF")))
    tops = np.zeros(len(TRIALS))
    for g in GROUPS:
        bars = sorted(_bars(ax, f"group:{g}"))
        tops = np.maximum(tops, [y + h for _, y, _, h in bars])
    assert np.allclose(tops, 100.0)  # the shares add up
    assert ax.get_ylim() == (0.0, 100.0) and ax.get_xlim()[0] < -0.375 and ax.get_xlim()[1] > 2.375  # all in view
    with pytest.raises(OptionError, match="emg-ten"):
        group_shares(results, workflows=["emg-ten"])


def test_trial_helpers(results):
    assert trial_order(results) == ["slow", "normal", "fast"]
    assert preferred_trial(results) == "normal"
    renamed = results.assign(trial=results["trial"].map({"slow": "p55", "normal": "p100", "fast": "p145"}))
    assert preferred_trial(renamed) == "p100"  # the middle speed


# ------------------------------------------------------------------------------- saving
def test_save_figure(tmp_path):
    fig = group_rates_over_cycle(make_timeseries(1.0), 60.0)
    paths = save_figure(fig, tmp_path / "figs", "groups")
    assert set(paths) == {"png", "svg"}
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in paths["svg"].read_bytes()[:2000]
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == [".musclemetab-files", "groups.png", "groups.svg"]
    with pytest.raises(OptionError):
        save_figure(fig, tmp_path, "../x")


# ------------------------------------------------------------------------------- report
def test_write_report(study, tmp_path):
    from musclemetab.report.draw import draw_figure
    from musclemetab.report.folder import read_study_folder

    out = write_report(study, workers=2)  # two worker processes draw the figures
    assert out == study / "report.html"
    # each file is the one drawn in this process
    folder = read_study_folder(study)
    for name in ("excitations_fiber_lengths", "group_shares", "phase_pies"):
        alone = draw_figure(folder, tmp_path, ("png",), name)
        assert Path(alone.paths["png"]).read_bytes() == (study / "figures" / f"{name}.png").read_bytes(), name
    text = out.read_text(encoding="utf-8")
    p = _parse(text)
    # one embedded figure per figure
    assert len(p.imgs) == len(FIGURE_NAMES)
    assert all(img["src"].startswith("data:image/png;base64,") for img in p.imgs)
    for name in FIGURE_NAMES:
        assert (study / "figures" / f"{name}.png").is_file() and not (study / "figures" / f"{name}.svg").exists()
        assert f'id="figure-{name}"' in text
    # figures come before the tables; no absolute path of the machine in the page
    assert text.index('id="figures"') < text.index('id="table-whole-body"')
    assert str(study) not in text
    # nothing external, no script
    assert "http" not in text and "<script" not in text.lower() and "<link" not in text.lower()
    # tables: subjects, whole-body, measured, cost of transport, phase shares, group shares, failures?, software
    for anchor in ("table-whole-body", "table-cost-of-transport", "table-phase-shares", "table-group-shares"):
        assert anchor in p.ids
    assert p.tables >= 7
    assert "W/kg" in text and "J/(kg·m)" in text and "Measured whole-body" in text
    # values: BH04 effort-ten normal mean over subjects appears in the whole-body table
    r = pd.read_csv(study / "results.csv")
    d = r[(r["model"] == "BH04") & (r["workflow"] == "effort-ten") & (r["trial"] == "normal")]["whole_body_W_per_kg"]
    assert f"{d.mean():.2f} [{d.std(ddof=1):.2f}]" in text
    # settings, escaping, software
    assert "speeds &lt;synthetic&gt; &amp; co" in text and "<synthetic>" not in text
    for s in SUBJECTS:
        assert f"<th scope=\"row\">{s}</th>" in text
    import casadi, matplotlib, scipy  # noqa: E401

    import musclemetab

    for pkg, ver in (("musclemetab", musclemetab.__version__), ("numpy", np.__version__), ("scipy", scipy.__version__),
                     ("casadi", casadi.__version__), ("pandas", pd.__version__),
                     ("matplotlib", matplotlib.__version__), ("opensim", "4.6-study")):
        assert f"<th scope=\"row\">{pkg}</th>" in text and ver in text
    assert "Method" in text and "None: every unit of the study succeeded" in text
    # atomic: no temporary file left anywhere
    leftovers = [q for q in study.rglob(".*") if q.name.startswith(".") and q.name != ".musclemetab-files"]
    assert leftovers == []


def test_report_notes_and_failures(tmp_path):
    root = make_study(tmp_path / "one", measured=False, trials={"normal": 1.25}, solutions=False,
                      failed={("s2", "normal", "effort-gen")})
    out = write_report(root, tmp_path / "elsewhere" / "page.html")
    assert out == tmp_path / "elsewhere" / "page.html"
    text = out.read_text(encoding="utf-8")
    p = _parse(text)
    notes = {
        "estimated_vs_measured": "no measured metabolic rate",
        "whole_body_over_cycle": "one speed only",
        "rates_against_speed": "one speed only",
        "excitations_fiber_lengths": "solution.sto: missing",
    }
    assert len(p.imgs) == len(FIGURE_NAMES) - len(notes)
    for name, note in notes.items():
        i = text.index(f'id="figure-{name}"')
        assert note in text[i:i + 1500]
        assert not (tmp_path / "elsewhere" / "figures" / f"{name}.png").exists()
    assert (tmp_path / "elsewhere" / "figures" / "phase_shares.png").is_file()
    assert "one speed only, no trend" not in text  # the note is in the figure, not the page
    # failures table lists the failed unit, escaped
    assert "solver did not converge &lt;maximum iterations&gt;" in text
    assert "No measured metabolic rate in the results" in text
    assert not (root / "report.html").exists()
    assert str(root) not in text.split('id="failures"')[0].split('id="method"')[1]  # notes name relative paths


def test_stale_figures_removed(tmp_path, monkeypatch):
    """A figure an earlier report wrote and this one cannot draw is removed; a file of the same
    name the report did not write (no record of it) is left alone."""
    small_figures(monkeypatch, tmp_path)
    root = make_study(tmp_path / "s", trials={"normal": 1.25})
    write_report(root, workers=1)
    assert (root / "figures" / "excitations_fiber_lengths.png").is_file()
    for folder in (root / "units").glob("*/*/*"):
        (folder / "solution.sto").unlink()
    write_report(root, workers=1, force=True)
    assert not (root / "figures" / "excitations_fiber_lengths.png").exists()
    other = make_study(tmp_path / "o", solutions=False, trials={"normal": 1.25})
    (other / "figures").mkdir()
    (other / "figures" / "excitations_fiber_lengths.png").write_bytes(b"not the report's")
    write_report(other, workers=1)
    assert (other / "figures" / "excitations_fiber_lengths.png").read_bytes() == b"not the report's"


def test_figures_never_written_through_a_symlink(tmp_path):
    """``figures`` a symbolic link to a folder beside the output: refused with the path named,
    nothing written or removed in the decoy folder."""
    root = make_study(tmp_path / "s", solutions=False, trials={"normal": 1.25})
    decoy = tmp_path / "decoy"
    decoy.mkdir()
    for name in ("estimated_vs_measured.png", "excitations_fiber_lengths.png", "notes.txt"):
        (decoy / name).write_bytes(b"foreign")
    (root / "figures").symlink_to(decoy, target_is_directory=True)
    with pytest.raises(OptionError, match="symbolic link") as err:
        write_report(root, workers=1)
    assert str(root / "figures") in str(err.value)
    assert sorted(p.name for p in decoy.iterdir()) == ["estimated_vs_measured.png",
                                                       "excitations_fiber_lengths.png", "notes.txt"]
    assert all(p.read_bytes() == b"foreign" for p in decoy.iterdir())
    assert not (root / "report.html").exists()


def test_report_errors(tmp_path):
    with pytest.raises(InputFileError, match="no such study folder"):
        write_report(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match=r"results\.csv: missing.*musclemetab run"):
        write_report(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    pd.DataFrame({"subject": ["s1"], "trial": ["normal"]}).to_csv(bad / "results.csv", index=False)
    with pytest.raises(MissingColumnError, match="workflow"):
        write_report(bad)
    ok = make_study(tmp_path / "j", solutions=False, trials={"normal": 1.25})
    (ok / "study.json").write_text("{not json")
    with pytest.raises(InputFileError, match="study.json"):
        write_report(ok)


def test_cli(study, tmp_path, capsys, monkeypatch):
    import argparse

    from musclemetab.commands.report import add_parser as add_report_parser

    small_figures(monkeypatch, tmp_path)

    parser = argparse.ArgumentParser(prog="musclemetab")
    add_report_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["report", str(study), "--out", str(tmp_path / "r.html"), "--svg"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    n = len(FIGURE_NAMES)
    assert f"{n} of {n} figures" in out and (tmp_path / "r.html").is_file()
    assert (tmp_path / "figures" / "phase_shares.svg").is_file()
    args = parser.parse_args(["report", str(tmp_path / "absent")])
    with pytest.raises(InputFileError, match="absent: no such study folder"):
        args.func(args)


def test_out_without_html_suffix_is_a_folder_holding_page_and_figures(study, tmp_path, capsys, monkeypatch):
    """``--out pages`` (a name like every other command's ``--out DIR``) makes the folder
    ``pages`` with the page and its figures inside; nothing is written beside it. A file there
    that is not a page is refused, naming it, before anything is drawn."""
    from musclemetab.commands import main

    small_figures(monkeypatch, tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["report", str(study), "--out", "pages", "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert f"page -> {Path('pages') / 'report.html'}" in printed
    assert sorted(p.name for p in work.iterdir()) == ["pages"]
    assert (work / "pages" / "report.html").is_file()
    assert (work / "pages" / "figures" / "phase_shares.png").is_file()
    (work / "notes.txt").write_text("mine")
    assert main(["report", str(study), "--out", "notes.txt"]) == 1
    err = capsys.readouterr().err
    assert "--out notes.txt: a file that is not an HTML page" in err and err.count("\n") == 1
    assert (work / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in work.iterdir()) == ["notes.txt", "pages"]


def test_output_closed_early_ends_quietly(study):
    """``musclemetab report DIR | head``: no traceback when the reader leaves; status 141."""
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    write_report(study)  # up to date: the command below only checks and prints
    cmd = [sys.executable, "-m", "musclemetab", "report", str(study)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    proc.stdout.close()  # the reader is gone before the command prints
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141 and err == "", err
    # as a user meets it: piped into head, which reads one line and leaves (the command may be done first)
    r = subprocess.run(" ".join(cmd) + " | head -1; exit ${PIPESTATUS[0]}", shell=True, executable="/bin/bash",
                       capture_output=True, text=True, env=env)
    assert r.returncode in (0, 141) and r.stderr == "" and r.stdout.startswith("report: ")


def test_report_when_every_unit_failed(tmp_path, capsys):
    root = tmp_path / "failed"
    root.mkdir()
    columns = ["subject", "trial", "workflow", "model", "speed_m_per_s", "status", "whole_body_W_per_kg", "unit_dir"]
    pd.DataFrame(columns=columns).to_csv(root / "results.csv", index=False)
    pd.DataFrame([{"subject": "s1", "trial": "", "workflow": "emg-ten", "reason": "EMG file missing"}]).to_csv(
        root / "failures.csv", index=False)
    text = write_report(root).read_text(encoding="utf-8")
    p = _parse(text)
    assert p.imgs == []
    assert text.count("no unit of the study succeeded: nothing to draw.") == len(FIGURE_NAMES)
    assert "No unit of the study succeeded: no results to tabulate." in text
    assert "(all trials)" in text and "EMG file missing" in text
    assert "study.json is missing" in text
    # the command says the one reason once, not once per figure
    from musclemetab.commands import main

    assert main(["report", str(root), "--force"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[1:] == ["  no figure drawn: no unit of the study succeeded: nothing to draw."], printed
    # a page or a demo folder where a file is: one line, nothing written
    (tmp_path / "afile").write_text("x")
    for argv in (["report", str(root), "--out", str(tmp_path / "afile" / "x.html")],
                 ["demo", "--speeds", "normal", "--out", str(tmp_path / "afile")]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{tmp_path / 'afile'} is an existing file, not a folder" in err, err
    assert (tmp_path / "afile").read_text() == "x"
    # a refused option of the demo leaves no folder, not even its study.toml
    (tmp_path / "priors.csv").write_text("a,b\n1,2\n")
    assert main(["demo", "--speeds", "normal", "--uncertainty", "2", "--uncertainty-priors", str(tmp_path / "priors.csv"),
                 "--out", str(tmp_path / "demo")]) == 1
    assert "priors.csv: no column parameter, spread" in capsys.readouterr().err and not (tmp_path / "demo").exists()


@pytest.mark.parametrize("cut", ["within the last row", "after the header"])
def test_a_results_table_cut_short_is_refused_naming_it(tmp_path, capsys, cut):
    """``results.csv`` cut short (a full disk, a copy stopped part-way) within its last row, or
    down to its header while ``failures.csv`` names no failed unit (every unit failing is the
    one way to a table without rows): ``musclemetab report`` refuses with one line naming the
    file and what to do, status 1, no page (it used to write "0 of 0 units succeeded", status 0)."""
    from musclemetab.commands import main

    root = make_study(tmp_path / "s", solutions=False, trials={"normal": 1.25})
    path = root / "results.csv"
    text = path.read_text()
    path.write_text(text[:-5] if cut == "within the last row" else text.splitlines(keepends=True)[0])
    assert main(["report", str(root)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"musclemetab: error: {path}: ") and len(err.splitlines()) == 1, err
    assert ("cut short" in err and "run the same 'musclemetab run STUDY.toml' again" in err), err
    assert not (root / "report.html").exists()


def test_report_is_rebuilt_only_when_its_inputs_change(tmp_path, monkeypatch):
    from musclemetab.report.build import generate_report, report_key

    small_figures(monkeypatch, tmp_path)

    copy = make_study(tmp_path / "copy", solutions=False, trials={"normal": 1.25})  # fewer figures to draw
    out, first = generate_report(copy)
    page = out.read_text(encoding="utf-8")
    png = copy / "figures" / "phase_shares.png"
    stamp = png.stat().st_mtime_ns
    # nothing changed: the page and the figures are left as they are
    out2, again = generate_report(copy)
    assert out2 == out and out.read_text(encoding="utf-8") == page and png.stat().st_mtime_ns == stamp
    assert [e.name for e in again] == [e.name for e in first] and [e.note for e in again] == [e.note for e in first]
    key = report_key(copy)
    assert f'content="{key}"' in page
    # a unit's record changes (a unit ran again): new key, the report is drawn again
    unit = next((copy / "units").glob("**/unit.json"))
    unit.write_text(unit.read_text(encoding="utf-8").replace("{", '{"rerun": 1, ', 1), encoding="utf-8")
    assert report_key(copy) != key
    generate_report(copy)
    assert png.stat().st_mtime_ns != stamp
    assert f'content="{report_key(copy)}"' in out.read_text(encoding="utf-8")
    # a missing figure file forces a rebuild too
    png.unlink()
    generate_report(copy)
    assert png.is_file()


def test_per_muscle_ranked_figure_values(study):
    from musclemetab.report.figures import per_muscle_ranked

    pm = pd.read_csv(study / "per_muscle.csv").merge(
        pd.read_csv(study / "results.csv").drop_duplicates(["subject", "trial"])[["subject", "trial", "speed_m_per_s"]],
        on=["subject", "trial"])
    fig = per_muscle_ranked(pm, workflow="effort-ten", models=["UM10", "BH04"], top=3)
    ax = fig.axes[0]
    # largest at the top, the three largest parts only
    ticks = sorted((t.get_position()[1], t.get_text()) for t in ax.get_yticklabels())[::-1]
    assert [name for _, name in ticks] == ["soleus", "gastrocnemius medialis", "vastus lateralis"]
    d = pm[(pm.workflow == "effort-ten") & (pm.model == "UM10")]
    for trial in ("slow", "normal", "fast"):
        bars = _bars(ax, f"trial:{trial}")
        want = d[d.trial == trial].groupby("muscle")["muscle_W_per_kg"].mean()
        widths = sorted((y, w) for _, y, w, _ in bars)[::-1]  # top bar first
        np.testing.assert_allclose([w for _, w in widths], want[["soleus_r", "gasmed_r", "vaslat_r"]], rtol=1e-12)
        assert all(x == 0.0 for x, _, _, _ in bars)
        # every bar in view
        assert max(w for _, w in widths) < ax.get_xlim()[1] and ax.get_xlim()[0] == 0.0
    # one colour per trial, the same in every panel; a shared axis
    assert fig.axes[0].get_shared_x_axes().joined(fig.axes[0], fig.axes[1])


def test_per_muscle_ranking_merges_two_model_families(study):
    """A subject on gait2392 (``med_gas_r``, ``soleus_r``) and one on Rajagopal (``gasmed_r``,
    ``soleus_r``): the ranking puts both names of the medial gastrocnemius in one bar, the mean
    over the two subjects (worked by hand); a muscle of two bundles (``add_mag1_r`` +
    ``add_mag2_r``) is their sum."""
    from musclemetab.report.figures import harmonise_muscles, per_muscle_ranked

    rows = [("a", "med_gas_r", 0.30), ("a", "soleus_r", 0.50), ("a", "add_mag1_r", 0.05), ("a", "add_mag2_r", 0.07),
            ("b", "gasmed_r", 0.20), ("b", "soleus_r", 0.40), ("b", "addmagDist_r", 0.04), ("b", "addmagMid_r", 0.06)]
    pm = pd.DataFrame([{"subject": s, "trial": "normal", "workflow": "effort-ten", "model": "UM10", "muscle": m,
                        "muscle_W_per_kg": v} for s, m, v in rows])
    h = harmonise_muscles(pm).set_index(["subject", "muscle"])["muscle_W_per_kg"]
    assert h[("a", "gastrocnemius medialis (r)")] == pytest.approx(0.30)
    assert h[("b", "gastrocnemius medialis (r)")] == pytest.approx(0.20)
    assert h[("a", "adductor magnus (r)")] == pytest.approx(0.12)
    # a subject solved on both legs: one leg is the mean of its two legs (0.2 and 0.4 W/kg)
    legs = pd.DataFrame([{"subject": "c", "trial": "normal", "workflow": "effort-ten", "model": "UM10", "muscle": m,
                          "side": m[-1], "muscle_W_per_kg": v} for m, v in (("gasmed_r", 0.2), ("gasmed_l", 0.4))])
    one = harmonise_muscles(legs)
    assert one["muscle"].tolist() == ["gastrocnemius medialis"] and one["muscle_W_per_kg"].tolist() == pytest.approx([0.3])
    fig = per_muscle_ranked(pm, top=3)
    ax = fig.axes[0]
    ticks = [t.get_text() for t in sorted(ax.get_yticklabels(), key=lambda t: -t.get_position()[1])]
    assert ticks == ["soleus (r)", "gastrocnemius medialis (r)", "adductor magnus (r)"]
    widths = sorted(((y, w) for _, y, w, _ in _bars(ax, "trial:normal")), reverse=True)
    np.testing.assert_allclose([w for _, w in widths], [0.45, 0.25, 0.11], rtol=1e-12)


def test_rates_against_speed_values(study):
    from musclemetab.report.figures import rates_against_speed

    r = pd.read_csv(study / "results.csv")
    fig = rates_against_speed(r, workflow="effort-ten", models=["UM10", "BH04"])
    ax, ax_g = fig.axes[0], fig.axes[1]  # per model: the whole body above, the groups on their own scale below
    d = r[(r.workflow == "effort-ten") & (r.model == "UM10")]
    for subject in SUBJECTS:  # each subject's own trials, in the order of its speeds
        ds = d[d.subject == subject].set_index("trial").loc[["slow", "normal", "fast"]]
        wb = next(ln for ln in ax.lines if ln.get_gid() == f"whole-body:{subject}")
        np.testing.assert_allclose(wb.get_xdata(), ds["speed_m_per_s"])
        np.testing.assert_allclose(wb.get_ydata(), ds["whole_body_no_basal_W_per_kg"])
        pf = next(ln for ln in ax_g.lines if ln.get_gid() == f"group:PF:{subject}")
        np.testing.assert_allclose(pf.get_ydata(), ds.share_PF_pct / 100 * ds.whole_body_no_basal_W_per_kg)
    # whole-body panels share one scale, group panels another
    assert fig.axes[0].get_shared_y_axes().joined(fig.axes[0], fig.axes[2])
    assert fig.axes[1].get_shared_y_axes().joined(fig.axes[1], fig.axes[3])
    assert not fig.axes[0].get_shared_y_axes().joined(fig.axes[0], fig.axes[1])
    # the speed axis spans the trials' speeds (m/s), the same in every panel, not the cycle's 0-100 %
    speeds = r[r.workflow == "effort-ten"]["speed_m_per_s"]
    for a in fig.axes[:4]:
        assert a.get_xlim() == pytest.approx((speeds.min() - 0.05, speeds.max() + 0.05))
    assert fig.axes[-1].get_xlabel() == "walking speed (m/s)"
    # black is the whole body's alone
    from matplotlib.colors import to_rgb

    assert to_rgb(wb.get_color()) == (0.0, 0.0, 0.0)
    assert all(to_rgb(ln.get_color()) != (0.0, 0.0, 0.0) for ln in ax_g.lines)


# ------------------------------------------------------------------- pies, colours, runs
def test_phase_pies_area_proportional_to_cost(results):
    from musclemetab.report.figures import phase_pies

    fig = phase_pies(results, workflow="effort-ten")
    ax = fig.axes[0]
    wedges = {p.get_gid(): p for p in ax.patches if p.get_gid()}
    d = results[results.workflow == "effort-ten"].groupby(["model", "trial"])[
        ["whole_body_no_basal_W_per_kg", "swing_energy_share_pct", "stance_energy_share_pct"]].mean()
    assert len(wedges) == 2 * len(d)
    ratio = []
    for (m, t), row in d.iterrows():
        stance, swing = wedges[f"stance:{m}:{t}"], wedges[f"swing:{m}:{t}"]
        assert stance.r == swing.r
        ratio.append(np.pi * stance.r**2 / row["whole_body_no_basal_W_per_kg"])  # area per W/kg
        # the swing wedge's angle is its share of the cycle's energy
        sweep = (swing.theta2 - swing.theta1) % 360.0
        assert sweep / 360.0 == pytest.approx(row["swing_energy_share_pct"] / 100.0, rel=1e-9)
        assert stance.get_facecolor()[:3] != swing.get_facecolor()[:3]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)  # area proportional to the total cost
    # the largest cost has the largest pie, of radius 0.46
    assert max(p.r for p in wedges.values()) == pytest.approx(0.46)


def test_palette_is_okabe_ito_and_distinct():
    from musclemetab.colours import GROUP_COLOURS, MODEL_COLOURS, WORKFLOW_COLOURS
    from musclemetab.metabolics.registry import ALL_MODELS
    from musclemetab.report.figures import group_colour

    # the eight colours published by Okabe and Ito (2008)
    okabe_ito = {"#000000", "#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00", "#CC79A7"}
    assert set(MODEL_COLOURS) == set(ALL_MODELS)
    assert set(MODEL_COLOURS.values()) == okabe_ito  # eight models, eight distinct colours
    assert len(set(WORKFLOW_COLOURS.values())) == len(WORKFLOW_COLOURS) and set(WORKFLOW_COLOURS.values()) <= okabe_ito
    groups = [group_colour(g) for g in GROUPS]
    assert len(set(groups)) == len(groups)
    # the lighter partner of a degree of freedom: the same hue mixed with white
    from matplotlib.colors import to_rgb

    he, hf = np.array(to_rgb(GROUP_COLOURS["HE"])), np.array(to_rgb(GROUP_COLOURS["HF"]))
    np.testing.assert_allclose(hf, he + 0.55 * (1 - he), atol=1 / 255)


def test_solver_runs_table_lists_every_unit(tmp_path):
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.page import render_page, solver_runs

    root = make_study(tmp_path / "runs", measured=False, trials={"normal": 1.25},
                      failed={("s2", "normal", "effort-gen")})
    rows = {tuple(r[:3]): r[3:] for r in solver_runs(read_study_folder(root))}
    assert len(rows) == len(SUBJECTS) * len(WORKFLOWS)
    for (subject, trial, workflow), (side, status, iterations, time_s, violation, residual, _) in rows.items():
        if (subject, workflow) == ("s2", "effort-gen"):
            assert (status, iterations) == ("Maximum_Iterations_Exceeded", "3000")
            continue
        assert (side, status, iterations) == ("right", "Solve_Succeeded", str(ITERATIONS[workflow]))
        assert (time_s, violation, residual) == ("1.25", "3.0e-07", "2.0e-06")
    page = render_page(read_study_folder(root), [])  # the page without figures
    start = page.index('<h2 id="solver-runs">')  # a heading followed by its text and table, never empty
    runs = page[start:page.index("</details>", start) + len("</details>")]
    assert _parse(runs).tables == 1
    assert "The muscle redundancy solve of every unit" in runs
    assert runs.count("Solve_Succeeded") == len(SUBJECTS) * len(WORKFLOWS) - 1
    assert "Maximum_Iterations_Exceeded" in runs


def test_report_key_follows_the_study_file(tmp_path):
    from musclemetab.report.build import generate_report, report_key

    root = tmp_path / "toml"  # a study whose units all failed: the page alone, drawn quickly
    root.mkdir()
    pd.DataFrame(columns=["subject", "trial", "workflow", "model", "status", "whole_body_W_per_kg"]).to_csv(
        root / "results.csv", index=False)
    pd.DataFrame([{"subject": "s1", "trial": "t", "workflow": "effort-gen", "reason": "an input of the test"}]).to_csv(
        root / "failures.csv", index=False)  # the failed units, as the runner lists them
    toml = tmp_path / "elsewhere" / "study.toml"
    toml.parent.mkdir()
    toml.write_text('name = "a"\n')
    (root / "study.json").write_text(json.dumps({"name": "a", "source": str(toml)}))
    out, _ = generate_report(root)
    key = report_key(root)
    assert f'content="{key}"' in out.read_text(encoding="utf-8")
    generate_report(root)
    assert report_key(root) == key
    toml.write_text('name = "b"\n')  # the study file changes, study.json does not
    assert report_key(root) != key
    generate_report(root)
    assert f'content="{report_key(root)}"' in out.read_text(encoding="utf-8")


def test_workers_option(study, tmp_path):
    from musclemetab.report.build import generate_report

    with pytest.raises(OptionError, match="workers"):
        generate_report(study, tmp_path / "w0" / "report.html", workers=0)
    # the default: the cores this process may use, at most one per figure, never the load
    from musclemetab.report.draw import default_workers

    cores = len(os.sched_getaffinity(0))
    assert default_workers() == cores and default_workers(1) == 1 and default_workers(100) == cores


def test_a_drawing_process_that_dies_leaves_no_figure_out(study, tmp_path, monkeypatch):
    """The copy takes the first (largest) figure and dies: the report's process draws it."""
    from musclemetab.report import draw
    from musclemetab.report.folder import read_study_folder

    def dies(conn, study, fig_dir, formats, order, plans, counter):
        with counter.get_lock():
            counter.value += 1  # claims order[0]
        os._exit(3)

    monkeypatch.setattr(draw, "_child_share", dies)
    # each small figure holds its name (a file in another's place differs); the pies drawn for real
    small_figures(monkeypatch, tmp_path, keep=("phase_pies",))
    folder = read_study_folder(study)
    entries = draw.make_figures(folder, tmp_path / "figs", workers=2)
    assert [e.name for e in entries] == list(FIGURE_NAMES)
    for e in entries:
        assert e.paths is not None and Path(e.paths["png"]).is_file(), e.name
    # the same files as drawn one after the other
    for name in ("excitations_fiber_lengths", "phase_pies"):
        alone = draw.draw_figure(folder, tmp_path / "alone", ("png",), name)
        assert Path(alone.paths["png"]).read_bytes() == (tmp_path / "figs" / f"{name}.png").read_bytes()


def test_measured_emg_over_the_excitations(tmp_path):
    from musclemetab.io import write_storage
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.plan import measured_emg

    root = make_study(tmp_path / "emg", trials={"normal": 1.25}, measured=False)
    # a measured envelope: two channels for the soleus (averaged), one for the tibialis
    t = np.arange(0.5, 1.9, 0.002)
    sol_a = 0.2 + 0.6 * np.exp(-(((t - 1.1) / 0.08) ** 2))
    sol_b = 0.1 + 0.5 * np.exp(-(((t - 1.1) / 0.08) ** 2))
    ta = 0.1 + 0.3 * np.exp(-(((t - 0.7) / 0.05) ** 2))
    write_storage(tmp_path / "emg.mot", pd.DataFrame({"SOL1": sol_a, "SOL2": sol_b, "TA": ta},
                                                      index=pd.Index(t, name="time")), in_degrees=False)
    (tmp_path / "map.json").write_text(json.dumps({"soleus_r": ["SOL1", "SOL2"], "tibant_r": ["TA"]}))
    settings = json.loads((root / "study.json").read_text())
    settings["subjects"]["s1"].update(emg_files={"normal": str(tmp_path / "emg.mot")},
                                      emg_mapping=str(tmp_path / "map.json"))
    (root / "study.json").write_text(json.dumps(settings))
    study = read_study_folder(root)
    folder = root / "units" / "s1" / "normal"
    sols = {w: Solution.load(folder / w) for w in WORKFLOWS}
    cycles = {w: CYCLE for w in WORKFLOWS}
    rows = study.ok[(study.ok.subject == "s1") & (study.ok.trial == "normal")]
    emg, label, text = measured_emg(study, "s1", "normal", sols, cycles, rows)
    assert set(emg) == {"soleus_r", "tibant_r"} and "peak" in label and "effort-ten" in text
    sol = sols["effort-ten"]
    keep = (sol.time_s >= CYCLE[0] - 1e-9) & (sol.time_s <= CYCLE[2] + 1e-9)
    nodes = sol.time_s[keep]
    for muscle, raw in (("soleus_r", (sol_a + sol_b) / 2), ("tibant_r", ta)):
        pct, v = emg[muscle]
        np.testing.assert_allclose(pct, 100 * (nodes - CYCLE[0]) / (CYCLE[2] - CYCLE[0]))
        envelope = np.interp(nodes, t, raw)
        peak = sol.excitation[keep, MUSCLES.index(muscle)].max()
        np.testing.assert_allclose(v, envelope * peak / envelope.max(), rtol=1e-9)  # peak = excitation peak (file: 1e-12)
    # an EMG-TEN unit of the trial: its scale factors and channels instead
    unit = root / "units" / "s1" / "normal" / "emg-ten"
    unit.mkdir()
    (unit / "summary.json").write_text(json.dumps({"emg_tracking": {"soleus_r": {"channels": ["SOL2"], "scale": 0.8}}}))
    rows = pd.concat([rows, rows.iloc[[0]].assign(workflow="emg-ten", unit_dir="units/s1/normal/emg-ten")])
    emg, label, _ = measured_emg(study, "s1", "normal", sols, cycles, rows)
    assert set(emg) == {"soleus_r"} and "EMG-TEN" in label
    np.testing.assert_allclose(emg["soleus_r"][1], 0.8 * np.interp(nodes, t, sol_b), rtol=1e-9)
    # drawn in the figure: a dashed grey line over the soleus' excitation
    fig = excitations_and_fiber_lengths(sols, cycles, muscles=["soleus_r"], emg=emg, emg_label=label)
    line = next(ln for ln in fig.axes[0].get_lines() if ln.get_gid() == "emg")
    np.testing.assert_allclose(line.get_ydata(), emg["soleus_r"][1])
    # no EMG recorded for a trial: nothing drawn, the caption says so
    emg, _, text = measured_emg(study, "s2", "normal", sols, cycles, rows)
    assert emg == {} and "No measured EMG" in text


def test_figure2_from_the_cache(study, tmp_path, monkeypatch):
    import hashlib

    from musclemetab.report import figures as figure2_module  # figure2_compact draws the report's Figure 2
    from musclemetab.report import draw
    from musclemetab.report.folder import read_study_folder

    folder = read_study_folder(study)
    cache = draw.figure_cache("figure2_soleus")["png"]
    first = draw.draw_figure(folder, tmp_path / "a", ("png",), "figure2_soleus")  # drawn, or cached by a test
    drawn = Path(first.paths["png"]).read_bytes()
    assert drawn.startswith(b"\x89PNG") and cache.read_bytes() == drawn  # kept after the first drawing
    # the SHA-256 of the content beside it, worked out here
    checksum = cache.with_name(cache.name + ".sha256")
    assert checksum.read_text().strip() == hashlib.sha256(drawn).hexdigest()
    # taken from the cache the next time: the figure is not drawn
    calls = []

    def counting(*args, **kwargs):  # a small stand-in: what matters below is whether it is drawn
        from matplotlib.figure import Figure

        calls.append(1)
        fig = Figure(figsize=(2, 1))
        fig.add_subplot().plot([0, 1], [1, 0])
        return fig

    monkeypatch.setattr(figure2_module, "figure2_compact", counting)
    again = draw.draw_figure(folder, tmp_path / "b", ("png", "svg"), "figure2_soleus")
    assert calls == [] and Path(again.paths["png"]).read_bytes() == drawn and again.caption == first.caption
    assert set(again.paths) == {"png"}  # PNG only, also when the report writes SVG
    # a truncated or altered cache file does not match its checksum: drawn again, and the copy, the
    # cache and its checksum are those of the new drawing
    for damaged in (drawn[: len(drawn) // 2], drawn[:-1] + bytes([drawn[-1] ^ 1])):
        cache.write_bytes(damaged)
        calls.clear()
        redrawn = Path(draw.draw_figure(folder, tmp_path / "c", ("png",), "figure2_soleus").paths["png"]).read_bytes()
        assert calls == [1] and redrawn.startswith(b"\x89PNG") and redrawn not in (drawn, damaged)
        assert cache.read_bytes() == redrawn
        assert checksum.read_text().strip() == hashlib.sha256(redrawn).hexdigest()
    # a cache file without its checksum (an earlier version's) is not trusted either
    checksum.unlink()
    calls.clear()
    draw.draw_figure(folder, tmp_path / "d", ("png",), "figure2_soleus")
    assert calls == [1] and checksum.is_file()
    assert draw.figure_cache("phase_shares") is None


def test_package_figures_drawn_ahead_into_the_cache(tmp_path, monkeypatch):
    """``draw_package_figures`` (which ``musclemetab demo`` runs while its units solve) puts the
    Figure-2 plot into an empty cache with the SHA-256 of its content beside it, and draws nothing
    when the cache holds it; the report then copies it (see test_figure2_from_the_cache)."""
    import hashlib

    from musclemetab.report import figures as figure2_module  # figure2_compact draws the report's Figure 2
    from musclemetab.report import draw

    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path / "cache"))
    cache = draw.figure_cache("figure2_soleus")["png"]
    assert not cache.exists()
    draw.draw_package_figures()
    data = cache.read_bytes()
    assert data.startswith(b"\x89PNG")
    assert cache.with_name(cache.name + ".sha256").read_text().strip() == hashlib.sha256(data).hexdigest()
    calls = []
    monkeypatch.setattr(figure2_module, "figure2_compact", lambda *a, **k: calls.append(1))
    draw.draw_package_figures()
    assert calls == [] and cache.read_bytes() == data


def test_figures_handed_out_largest_first_by_their_measured_drawing_times(tmp_path, monkeypatch):
    """Each drawing's processor time is kept in the cache; the next report hands the figures
    out by it, largest first, a figure never timed first of all."""
    import json
    import time

    from musclemetab.report import draw
    from musclemetab.report.folder import read_study_folder

    small_figures(monkeypatch, tmp_path)  # only the figures' drawing times are read here
    folder = read_study_folder(make_study(tmp_path / "s", solutions=False, measured=False, trials={"normal": 1.25}))
    assert draw.draw_costs() == {}
    t0 = time.perf_counter()
    entries = draw.make_figures(folder, tmp_path / "a", workers=1)
    wall = time.perf_counter() - t0
    # every figure has a drawing function here; some end in a note (no solution, one speed): timed too
    timed = {e.name: e.draw_s for e in entries}
    assert entries[FIGURE_NAMES.index("excitations_fiber_lengths")].paths is None
    costs = draw.draw_costs()
    assert set(costs) == set(FIGURE_NAMES)  # the package's figure under its name: not in the cache yet
    for name, seconds in timed.items():
        assert 0 < seconds < wall and costs[name] == pytest.approx(seconds, abs=1e-4), name
    # the package's figure is in the cache now: its copy is timed apart from its drawing
    draw.make_figures(folder, tmp_path / "b", workers=1)
    assert set(draw.draw_costs()) == set(FIGURE_NAMES) | {"figure2_soleus (cached)"}

    # times chosen here: the order a drawing process receives is theirs, largest first
    chosen = {n: float(i) for i, n in enumerate(FIGURE_NAMES) if n != "group_shares"}  # group_shares: never timed
    chosen["figure2_soleus (cached)"] = chosen.pop("figure2_soleus")
    (tmp_path / "cache" / "figures" / "draw_costs.json").write_text(json.dumps(chosen))
    seen = tmp_path / "order.json"

    def records_order(conn, study, fig_dir, formats, order, plans, counter):
        seen.write_text(json.dumps(list(order)))
        os._exit(0)  # draws nothing: the report's process draws every figure

    monkeypatch.setattr(draw, "_child_share", records_order)
    entries = draw.make_figures(folder, tmp_path / "c", workers=2)
    assert [e.paths is None for e in entries] == [timed_entry.paths is None for timed_entry in
                                                  draw.make_figures(folder, tmp_path / "d", workers=1)]
    by_time = {n.removesuffix(" (cached)"): t for n, t in chosen.items()}
    assert json.loads(seen.read_text()) == ["group_shares"] + sorted(by_time, key=lambda n: -by_time[n])


def test_muscle_heat_map_one_row_of_panels_per_trial_by_speed(tmp_path):
    """With several trials the heat map has one row of panels per trial, ordered by walking
    speed (not by name), one panel per model titled ``trial: model``; each panel's array is
    that trial's per-muscle rates (metabolics.sto: total - basal, divided by the body mass)."""
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.plan import heat_map_figure, select

    trials = {"b_fast": 1.75, "a_slow": 0.75}  # names sort against speed
    root = make_study(tmp_path / "s", solutions=False, trials=trials)
    study = read_study_folder(root)
    sel = select(study)
    fig, caption = heat_map_figure(study, sel)
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels] == [f"{t}: {m}" for t in ("a_slow", "b_fast") for m in MODELS]
    assert "one row of panels per trial (a_slow, b_fast" in caption
    mass = SUBJECTS[sel.subject][0]
    for ax in panels:
        trial, model = ax.get_title().split(": ")
        cols = write_metabolics_sto(tmp_path / "cols", trials[trial] * (1 + 0.04 * list(SUBJECTS).index(sel.subject)))
        order = [x.get_text() for x in panels[0].get_yticklabels()]
        assert len(order) == len(MUSCLE_PARTS)
        want = np.vstack([cols[f"{model}/{mu}/total"] - cols[f"{model}/{mu}/basal"] for mu in MUSCLE_PARTS]) / mass
        got = np.asarray(ax.images[0].get_array())
        # the same rows, in the figure's muscle-group order
        np.testing.assert_allclose(np.sort(got, axis=0), np.sort(want, axis=0), rtol=1e-9)


def test_muscle_heat_map_holds_each_muscles_rate_over_the_cycle(tmp_path):
    """The heat map's arrays are the unit's per-muscle rates (metabolics.sto: total - basal)
    at the nodes inside the gait cycle, divided by the body mass, muscles ordered by group
    (PF before KE before HE), the toe-off marked; the nodes of the padding are left out."""
    from musclemetab.io.storage import write_storage
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.plan import heat_map_figure, select

    root = make_study(tmp_path / "s", solutions=False, trials={"normal": 1.25})
    folder = root / "units" / "s1" / "normal" / "effort-ten"
    t = np.round(np.arange(CYCLE[0] - 0.05, CYCLE[2] + 0.05 + 1e-9, 0.01), 6)  # padding on both sides
    muscles = ("glmax1_r", "soleus_r", "vaslat_r")  # HE, PF, KE: drawn PF, KE, HE
    cols = {}
    for k, model in enumerate(MODELS):
        for j, mu in enumerate(muscles):
            total = 10.0 * (k + 1) + (j + 1) * np.sin(np.pi * (t - CYCLE[0]) / (CYCLE[2] - CYCLE[0])) ** 2
            cols[f"{model}/{mu}/total"] = total
            cols[f"{model}/{mu}/basal"] = np.full(t.size, 0.1 * (j + 1))
    write_storage(folder / "metabolics.sto", pd.DataFrame(cols, index=pd.Index(t, name="time")))
    study = read_study_folder(root)
    sel = select(study)
    assert (sel.subject, sel.trial, sel.workflow) == ("s1", "normal", "effort-ten")
    fig, caption = heat_map_figure(study, sel)
    mass = SUBJECTS["s1"][0]
    inside = (t >= CYCLE[0] - 1e-9) & (t <= CYCLE[2] + 1e-9)
    assert "toe-off" in caption and "s1" in caption
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels] == list(MODELS)  # the order of study.json
    for ax in panels:
        image = ax.images[0]
        model = ax.get_title()
        want = np.vstack([(cols[f"{model}/{mu}/total"] - cols[f"{model}/{mu}/basal"])[inside] / mass
                          for mu in ("soleus_r", "vaslat_r", "glmax1_r")])
        np.testing.assert_allclose(np.asarray(image.get_array()), want, rtol=1e-9)  # the file keeps 12 digits
        assert np.allclose(_lines(ax, "toe-off")[0].get_xdata(), TOE_OFF_PCT)
    labels = [x.get_text() for x in panels[0].get_yticklabels()]
    assert labels == ["soleus (soleus_r) [PF]", "vastus lateralis (vaslat_r) [KE]", "gluteus maximus (glmax1_r) [HE]"]


def test_speed_series_never_match_trials_of_two_subjects_by_name():
    """Subject a walked ``normal`` (1.3 m/s) and ``fast`` (1.8 m/s), subject b ``walk1`` (1.2 m/s)
    and ``walk2`` (1.6 m/s): each subject's line runs through its own trials in the order of its
    speeds; no line joins a's ``normal`` with b's ``walk1``."""
    from musclemetab.report.figures import rates_against_speed

    rows = [("a", "normal", 1.3, 9.6), ("a", "fast", 1.8, 12.0), ("b", "walk2", 1.6, 6.5), ("b", "walk1", 1.2, 5.0)]
    r = pd.DataFrame([{"subject": s, "trial": t, "workflow": "effort-ten", "model": "UM10", "status": "ok",
                       "speed_m_per_s": v, "whole_body_W_per_kg": w + 1.2, "whole_body_no_basal_W_per_kg": w, "share_PF_pct": 40.0}
                      for s, t, v, w in rows])
    fig = rates_against_speed(r)
    lines = {ln.get_gid(): ln for ax in fig.axes for ln in ax.lines}
    assert set(lines) == {"whole-body:a", "whole-body:b", "group:PF:a", "group:PF:b"}
    assert lines["whole-body:a"].get_xdata().tolist() == [1.3, 1.8]
    assert lines["whole-body:a"].get_ydata().tolist() == [9.6, 12.0]
    assert lines["whole-body:b"].get_xdata().tolist() == [1.2, 1.6]  # walk1 before walk2: by speed
    assert lines["whole-body:b"].get_ydata().tolist() == [5.0, 6.5]
    np.testing.assert_allclose(lines["group:PF:b"].get_ydata(), [2.0, 2.6])


def test_the_papers_six_models_by_default_others_on_request(tmp_path, capsys, monkeypatch):
    """LW05 and MA68 rows in the results: left out of the figures unless asked for (``models``,
    ``--models``, ``[report] models`` recorded in study.json); the tables keep every model; the
    rebuild key follows the option; a model the study did not compute is refused by name."""
    import argparse

    from musclemetab.commands.report import add_parser as add_report_parser
    from musclemetab.report.build import generate_report
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.plan import select

    small_figures(monkeypatch, tmp_path, keep=("phase_pies",))  # the pies of the default models are drawn
    root = make_study(tmp_path / "s", solutions=False, trials={"slow": 0.75, "normal": 1.25})
    r = pd.read_csv(root / "results.csv")
    extra = pd.concat([r[r.model == "UM10"].assign(model=m, whole_body_W_per_kg=r.whole_body_W_per_kg + 5) for m in ("LW05", "MA68")])
    pd.concat([r, extra]).to_csv(root / "results.csv", index=False)
    assert select(read_study_folder(root)).models == list(MODELS)
    assert select(read_study_folder(root, models="all,LW05")).models == [*MODELS, "LW05"]
    assert set(select(read_study_folder(root, models="MA68")).ok["model"]) == {"MA68"}
    with pytest.raises(OptionError, match="--models: UM03 not computed"):
        read_study_folder(root, models="UM03")
    out, entries = generate_report(root, workers=1)
    pies = next(e for e in entries if e.name == "phase_pies")
    text = out.read_text(encoding="utf-8")
    assert "LW05" in text.split('id="results"')[1]  # the tables keep every model
    key = text.split('name="musclemetab-report-key" content="')[1][:64]
    assert pies.paths is not None
    parser = argparse.ArgumentParser(prog="musclemetab")
    add_report_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["report", str(root), "--models", "all,LW05,MA68", "--workers", "1"])
    assert args.func(args) == 0
    key2 = (root / "report.html").read_text(encoding="utf-8").split('name="musclemetab-report-key" content="')[1][:64]
    assert key2 != key
    settings = json.loads((root / "study.json").read_text())
    settings["report"] = {"models": ["LW05"]}
    (root / "study.json").write_text(json.dumps(settings))
    assert select(read_study_folder(root)).models == ["LW05"]


def test_flagged_units_and_failures_at_the_top_figures_numbered_in_page_order(tmp_path, monkeypatch):
    """A unit with a large reserve (results.csv flag, its share from summary.json) and a failed
    unit are named before the figures; the figures are numbered 1, 2, ... in page order."""
    import re

    from musclemetab.report.plan import FIGURE_TITLES

    small_figures(monkeypatch, tmp_path)
    root = make_study(tmp_path / "s", solutions=False, trials={"normal": 1.25}, failed={("s2", "normal", "effort-gen")})
    r = pd.read_csv(root / "results.csv")
    r["large_reserve"] = (r.subject == "s3") & (r.workflow == "effort-ten")
    r.to_csv(root / "results.csv", index=False)
    (root / "units/s3/normal/effort-ten/summary.json").write_text(json.dumps(
        {**RunRecord(status="Solve_Succeeded", success=True, iterations=40).to_dict(),
         "reserve_share_of_peak_moment": 0.31, "large_reserve": True}))
    text = write_report(root, workers=1).read_text(encoding="utf-8")
    top = text[text.index('id="attention"'):text.index('id="figures"')]
    assert "1 unit did not succeed" in top
    assert re.search(r"<td>s3</td><td>normal</td><td>effort-ten</td><td>large_reserve</td><td>[^<]*31\.0 %", top.replace(
        '<th scope="row">', "<td>").replace("</th>", "</td>"))
    numbers = [(int(n), t) for n, t in re.findall(r'<h3 id="figure-[^"]+">Figure (\d+)\. ([^<]+)</h3>', text)]
    assert [n for n, _ in numbers] == list(range(1, len(FIGURE_NAMES) + 1))
    assert [t for _, t in numbers] == [FIGURE_TITLES[n].replace("'", "&#39;") for n in FIGURE_NAMES]


def test_figure2_compact_holds_the_models_curves_on_shared_axes():
    """The compact Figure 2: the paper's six models in columns, each line the model's rate or
    efficiency of figure2_data at one activation; every panel of a row shares its axes."""
    from musclemetab.metabolics.figure2 import figure2_data
    from musclemetab.metabolics.registry import STUDY_MODELS
    from musclemetab.report.figures import figure2_compact

    data = figure2_data(models=STUDY_MODELS, n_velocity=41, n_length=31)
    fig = figure2_compact(data)
    axes = np.array(fig.axes).reshape(4, len(STUDY_MODELS))
    assert [ax.get_title() for ax in axes[0]] == list(STUDY_MODELS)
    for j, m in enumerate(STUDY_MODELS):
        for i, (key, plane) in enumerate((("rate_W", "velocity"), ("efficiency", "velocity"), ("rate_W", "length"),
                                          ("efficiency", "length"))):
            ax = axes[i, j]
            assert ax.get_shared_y_axes().joined(ax, axes[i, 0])
            assert ax.get_shared_x_axes().joined(ax, axes[0 if plane == "velocity" else 2, 0])
            for k, a in enumerate(data["activations"]):
                ln = _lines(ax, f"{key}:{plane}:{m}:a={a:g}")[0]
                np.testing.assert_array_equal(ln.get_ydata(), data[plane][key][m][k])
    assert axes[0, 0].get_ylim() == axes[0, 5].get_ylim()
