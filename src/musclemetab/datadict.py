"""The data dictionary: every column of every table the package writes, with unit and meaning.

:data:`DATA_DICTIONARY` is the one source; :func:`data_dictionary_table` gives it as a
table, :func:`write_data_dictionary` writes it as CSV (the study runner writes
``data_dictionary.csv`` beside ``results.csv``) and :func:`data_dictionary_markdown` renders
``docs/data_dictionary.md``. Column names with ``<...>`` stand for a family of columns
(``share_<G>_pct``: one per muscle group of ``muscle_groups.csv``).

Conventions: one leg means the simulated leg's muscles; whole body means both legs (twice
the simulated leg, or the two legs added when a study solves both: column ``legs``) per kg
of body mass; "no basal" means without any basal heat. One name has one meaning in every
file: ``whole_body_...`` columns are both legs with the basal heat their name states,
``leg_muscles_...`` one leg's muscles without basal heat, ``muscle_...`` one muscle without
basal heat; a file of one leg never holds a whole-body figure. ``results.csv`` and
``per_muscle.csv`` of earlier releases (``mean_W_per_kg``, ``mean_W_per_kg_no_basal``,
``one_leg_mean_W``; ``mean_W``, ``mean_W_per_kg``) are read by the report through
:data:`musclemetab.report.folder.RENAMED_RESULTS_COLUMNS`.
"""

from __future__ import annotations

import os

__all__ = ["DATA_DICTIONARY", "data_dictionary_table", "write_data_dictionary", "data_dictionary_markdown",
           "describe"]

_STUDY = "results.csv/.parquet"
_UNIT_WB = "whole_body.csv"
_UNIT_AN = "analysis.csv"
_PM = "per_muscle.csv/.parquet"
_LEGS_WB = "whole_body.csv (metabolics, legs added)"
_LEG = "leg_muscles.csv"
_SENS = "sensitivity.csv"
_ASSIST = "assistance.csv"

#: ``(files, column, unit, description)``; ``files`` lists the tables holding the column.
DATA_DICTIONARY: tuple[tuple[str, str, str, str], ...] = (
    # identifiers
    (f"{_STUDY}, {_PM} (study), failures.csv, {_ASSIST}", "subject", "-", "subject name of the study file"),
    (f"{_STUDY}, {_PM} (study), failures.csv, {_ASSIST}", "trial", "-", "trial name of the study file"),
    (f"{_STUDY}, {_PM} (study), failures.csv, {_ASSIST}", "workflow", "-",
     "muscle redundancy workflow: effort-gen, effort-cal, effort-ten or emg-ten"),
    (f"{_STUDY}, {_UNIT_WB}, {_UNIT_AN}, {_PM}, {_LEG}, {_LEGS_WB}, timeseries.csv, metabolics.parquet, {_SENS}, "
     f"{_ASSIST}", "model",
     "-",
     "metabolic energy model (short name of the registry, e.g. UM10, BH04)"),
    ("failures.csv", "reason", "-", "why the unit failed or was stopped (one line)"),
    (f"{_STUDY}, failures.csv", "status", "-", "results: ok for a unit whose results are in the row; failures.csv: "
     "failed (the unit did not succeed) or interrupted (stopped by Ctrl-C, or not reached by a run that Ctrl-C "
     "stopped; its previous folder is kept and the next run does it)"),
    (_STUDY, "unit_dir", "-", "the unit's folder, relative to the study folder (for legs 'r + l': the folder "
     "holding the two legs' unit folders r/ and l/)"),
    (f"{_STUDY}, {_LEGS_WB}", "legs", "-",
     "how the whole-body columns count the legs: '2 x r' or '2 x l' (that leg solved, doubled) or 'r + l' (side = "
     "both: each leg solved over its own gait cycle, the two added; leg_muscles_W, leg_energy_J, duration_s, "
     "toe_off_pct and speed are the legs' means, the energy shares are of both legs' energy, and the event times "
     "are empty: each leg's are in its unit folder); 'r+l' in the metabolics command's sum of two legs"),
    # whole body
    (f"{_STUDY}, {_UNIT_WB}, {_LEGS_WB}", "whole_body_W_per_kg", "W/kg",
     "whole-body average metabolic rate over the gait cycle: both legs (the two legs added when both "
     "were solved, otherwise twice the simulated leg) per kg of body mass, with the basal heat of the basal rule"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEGS_WB}", "whole_body_no_basal_W_per_kg", "W/kg",
     "whole_body_W_per_kg without any basal heat (both legs' muscles per kg of body mass)"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEG}", "leg_muscles_W", "W",
     "cycle-average summed rate of one leg's muscles (the simulated leg), no basal heat"),
    (_LEG, "leg_muscles_W_per_kg", "W/kg", "leg_muscles_W per kg of body mass (one leg, no basal heat)"),
    (_LEGS_WB, "<side>_leg_muscles_W", "W", "leg_muscles_W of that leg (r or l), over its own gait cycle"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEGS_WB}", "basal_rule", "-",
     "basal heat rule: body (1.2 W per kg of body mass added), muscle (1.2 W per kg of muscle mass in every "
     "muscle) or none"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEGS_WB}", "basal_W_per_kg", "W/kg",
     "basal heat added to the whole-body rate under the body rule: basal coefficient x body mass^basal exponent "
     "/ body mass (1.2 by default); 0 under the muscle and none rules"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEG}", "duration_s", "s", "duration the cycle average is taken over"),
    (f"{_STUDY}, {_UNIT_WB}", "gross_cost_of_transport_J_per_kg_per_m", "J/(kg m)",
     "gross cost of transport: whole_body_W_per_kg (with basal heat) divided by the walking speed"),
    (f"{_STUDY}, {_UNIT_WB}", "net_cost_of_transport_J_per_kg_per_m", "J/(kg m)",
     "net cost of transport: whole_body_no_basal_W_per_kg divided by the walking speed"),
    # cycle and phases
    (f"{_STUDY}, {_UNIT_AN}", "cycle_start_s", "s", "initial contact starting the gait cycle"),
    (f"{_STUDY}, {_UNIT_AN}", "toe_off_s", "s", "toe-off of the simulated leg"),
    (f"{_STUDY}, {_UNIT_AN}", "cycle_end_s", "s", "next initial contact of the same leg"),
    (f"{_STUDY}, {_UNIT_AN}", "toe_off_pct", "%", "toe-off in % of the gait cycle"),
    (f"{_STUDY}, {_UNIT_AN}", "leg_energy_J", "J",
     "metabolic energy of the simulated leg's muscles over the sampled cycle, no basal"),
    (f"{_STUDY}, {_UNIT_AN}", "stance_energy_share_pct", "%",
     "share of the cycle's muscle energy (one leg, no basal) spent in stance (initial contact to toe-off); "
     "an energy share, not a phase duration"),
    (f"{_STUDY}, {_UNIT_AN}", "swing_energy_share_pct", "%",
     "share of the cycle's muscle energy (one leg, no basal) spent in swing (toe-off to the next initial contact)"),
    (f"{_STUDY}, {_UNIT_AN}", "stance_energy_share_with_basal_pct", "%",
     "stance energy share with the per-muscle basal heat included"),
    (f"{_STUDY}, {_UNIT_AN}", "swing_energy_share_with_basal_pct", "%",
     "swing energy share with the per-muscle basal heat included"),
    (f"{_STUDY}, {_UNIT_AN}", "share_<G>_pct", "%",
     "share of muscle group G (key: muscle_groups.csv) in the cycle's muscle energy (one leg, no basal); each "
     "muscle's rate is split over the DOFs it spans by moment-arm ratio; the groups and share_other_pct sum to 100"),
    (f"{_STUDY}, {_UNIT_AN}", "share_other_pct", "%",
     "share of the muscle energy at instants when a muscle has no moment arm above the threshold"),
    (_STUDY, "speed_m_per_s", "m/s", "walking speed (study file, or estimated: see speed_source)"),
    (_STUDY, "measured_W_per_kg", "W/kg", "measured whole-body metabolic rate (indirect calorimetry), if given"),
    (f"{_STUDY}, {_UNIT_WB}, {_LEGS_WB}, {_LEG}", "muscle_mass_rule", "-",
     "how the muscle masses of the metabolic models were found: 'volume (body mass, height)' (the anatomical "
     "volume rule), or 'model (F0 / specific tension x density x lMo)' (OpenSim's probes' rule) when no height "
     "was given"),
    (_STUDY, "cycle_source", "-", "where the gait events come from (study file, ground reaction forces, or estimated)"),
    (_STUDY, "speed_source", "-", "where the walking speed comes from (study file, or estimated from the pelvis)"),
    (_STUDY, "solve_start", "-",
     "how the unit's solve started: 'cold' (static optimisation), 'warm from <workflow>' (the same trial's solution of "
     "the workflow before it), or 'cold: <reason>' when a planned warm start was not used or did not succeed "
     "(docs/study.md, warm-started chains); legs that differ are named"),
    (_STUDY, "other_start_rate_difference", "-",
     "with [solver] best_start (the unit solved from both starts, the lower objective kept): the other start's "
     "whole-body rate relative to the kept solution's, minus 1 (docs/study.md, Which optimum); two legs: their "
     "mean; the column is absent otherwise"),
    (_STUDY, "large_reserve", "-",
     "true when the solve's largest reserve RMS exceeds 1 % of the peak joint moment (the muscles do not explain "
     "the moments: check the inputs); summary.json holds reserve_share_of_peak_moment"),
    (_STUDY, "excluded_muscles", "-",
     "the muscles the solve left out (--exclude-muscles, the study file's exclude_muscles), names separated by "
     "spaces, both legs' for legs added; empty when none: the row's rates are those of the other muscles "
     "(flag excluded_muscles)"),
    (_STUDY, "gait_cycle", "-",
     "true when the rates are averaged over one gait cycle: gait events bound the span (not a solve over an explicit "
     "--window analysed without a cycle of its own) and its duration (duration_s) lies within walking's 0.8-2.0 s; "
     "false raises the flag not_a_gait_cycle"),
    (_STUDY, "quality", "-",
     "ok, or the unit's plausibility flags as code(names ...) joined by '; ': passive_force, fiber_length, "
     "saturated_activation, saturated_lengthening, reserve (the solve's, every leg's: muscles or DOFs named), metabolic_rate (the row's "
     "whole-body rate outside 0.5-2 x Ralston's 1958 rate at its speed, or above 7.34 W/kg without a speed), "
     "negative_group_rate (groups named), not_a_gait_cycle (the span named), excluded_muscles (muscles named); 'not "
     "checked' for a unit run by an earlier version; thresholds and sources in docs/quality.md"),
    # per muscle
    (f"{_PM}, metabolics.parquet, {_SENS}, factors.csv", "muscle", "-", "muscle name of the model"),
    (f"{_PM}, {_LEG}", "side", "-", "leg of the row's muscle(s): r or l ('' when a muscle name has no side suffix)"),
    (_PM, "muscle_W", "W",
     "the muscle's cycle-average metabolic rate without basal heat (work + activation/maintenance heat + "
     "shortening/lengthening heat); summed over a leg's muscles it is leg_muscles_W"),
    (_PM, "muscle_W_per_kg", "W/kg", "muscle_W per kg of body mass (this muscle of one leg, no basal heat)"),
    (_PM, "energy_per_cycle_J", "J", "the muscle's energy over the sampled gait cycle, no basal (stance_J + swing_J)"),
    (_PM, "share_of_leg_pct", "%", "the muscle's part of its leg's summed muscle_W (a leg's muscles sum to 100)"),
    (_PM, "stance_J", "J", "the muscle's energy in stance, no basal (empty without a gait cycle)"),
    (_PM, "swing_J", "J", "the muscle's energy in swing, no basal (empty without a gait cycle)"),
    (_PM, "work_mean_W", "W", "cycle average of the mechanical work rate the model counts"),
    (_PM, "activation_maintenance_heat_mean_W", "W", "cycle average of the activation and maintenance heat rate"),
    (_PM, "shortening_lengthening_heat_mean_W", "W", "cycle average of the shortening and lengthening heat rate"),
    (_PM, "basal_heat_mean_W", "W",
     "the muscle's basal heat (1.2 W per kg of muscle mass); apart, never inside muscle_W"),
    (_PM, "rank", "-", "rank of the muscle by muscle_W within its unit and model (1 = largest)"),
    # uncertainty bands (docs/uncertainty.md)
    (f"{_STUDY}, {_PM}", "<rate>_p05", "as <rate>",
     "low end of the band of the column <rate> (a rate, energy, cost of transport or energy share) over the plausible "
     "uncertainty samples of the row's trial unit (study file [uncertainty], --uncertainty N): its 5 % quantile from "
     "20 samples on, their minimum below (uncertainty_band); beside each rate when the study has samples"),
    (f"{_STUDY}, {_PM}", "<rate>_p50", "as <rate>", "median of <rate> over the plausible uncertainty samples"),
    (f"{_STUDY}, {_PM}", "<rate>_p95", "as <rate>",
     "high end of the band of <rate>: its 95 % quantile over the plausible uncertainty samples from 20 samples on, "
     "their maximum below"),
    (f"{_STUDY}, {_PM}", "uncertainty_samples", "-",
     "number of uncertainty samples behind the row's bands: converged and without a plausibility flag (every "
     "converged one with [uncertainty] keep_flagged); with side = both, a sample counts when both legs do"),
    (f"{_STUDY}, {_PM}", "uncertainty_rejected", "-",
     "number of the unit's uncertainty samples left out of the row's bands: a plausibility flag (unless "
     "keep_flagged) or a solve that did not converge"),
    (f"{_STUDY}, {_PM}", "uncertainty_band", "-",
     "what the band is: '5-95 %' (quantiles, from 20 samples), 'min-max' (fewer), 'min-max, few samples' (fewer than "
     "10 samples used: read with care), 'none'"),
    (f"{_STUDY}, {_PM}", "uncertainty_top_parameters", "as the rate",
     "the three muscle parameters whose priors give the rate (whole_body_W_per_kg; a muscle's muscle_W) the largest "
     "standard deviation to first order, '<parameter> <muscle> <SD>': |d rate/d log p| (sensitivity.csv) x the "
     "prior's spread; empty without sensitivities (--sensitivity)"),
    (_STUDY, "uncertainty_flagged_samples", "-",
     "the unit's samples with a plausibility flag or a solve that did not converge, '<sample>: <flags>' "
     "(flags as in quality), '(kept)' when keep_flagged kept it in the bands"),
    (_STUDY, "whole_body_W_per_kg_nominal_quantile", "-",
     "where the nominal whole_body_W_per_kg lies among the samples used for its band: the share of them below it "
     "(ties half), 0-1"),
    (_STUDY, "uncertainty_note", "-",
     "where the nominal whole_body_W_per_kg lies against its band, in words; when outside it, why (how many samples "
     "lie on the other side, the band's skew, flagged samples left out on the nominal's side, the nominal's own "
     "flags, few samples)"),
    *(("factors.csv", name, "-", f"factor of an uncertainty sample on the muscle's {what} (priors: docs/uncertainty.md)")
      for name, what in (("F0", "maximal isometric force"), ("lMo", "optimal fiber length"),
                         ("lTs", "tendon slack length"), ("kT", "tendon stiffness"),
                         ("kPE", "passive force-length stiffness kPE"), ("s0", "passive force-length shift s0"),
                         ("sM", "passive force-length strain sM"), ("muscle_mass", "mass (metabolic models)"),
                         ("slow_twitch_fraction", "slow-twitch fraction (metabolic models; the result clipped to 0-1)"))),
    ("factors.csv", "height", "-", "factor of an uncertainty sample on the subject's height (muscle-volume rule), the "
     "same on every row"),
    # time series
    ("timeseries.csv, ik_marker_errors.csv", "time_s", "s",
     "time: of the solver node (timeseries.csv), of the marker frame (ik_marker_errors.csv)"),
    ("timeseries.csv", "cycle_pct", "%", "time in % of the gait cycle"),
    ("timeseries.csv", "series", "-", "leg_muscles (summed muscles of one leg) or group/<G>"),
    ("timeseries.csv, metabolics.parquet", "value_W", "W",
     "metabolic rate of the row's series (timeseries.csv: one leg's muscles, no basal) or component "
     "(metabolics.parquet)"),
    ("metabolics.parquet", "time", "s", "time of the solver node (padding nodes trimmed)"),
    ("metabolics.parquet", "component", "-",
     "work, activation_maintenance, shortening_lengthening, basal (the per-muscle basal heat), total_no_basal "
     "(the sum of the first three: the muscle's rate without basal heat), and model extras (e.g. BH04's "
     "activation and maintenance, which split activation_maintenance)"),
    ("metabolics.sto", "<model>/<muscle>/<component>", "W", "the rates of metabolics.parquet as an OpenSim storage"),
    # solver and OpenSim files
    ("solution.sto", "/forceset/<muscle>/<quantity>", "see summary.json conventions",
     "solver states and forces: excitation, activation, normalized_fiber_length, normalized_fiber_velocity, "
     "tendon_force (N), active_fiber_force (N), passive_fiber_force (N), multipliers"),
    ("solution.sto", "/forceset/reserve_<dof>", "N m", "reserve actuator moment"),
    ("states.sto", "/jointset/<joint>/<coordinate>/value", "rad or m", "coordinate value from the IK motion"),
    ("states.sto", "/jointset/<joint>/<coordinate>/speed", "rad/s or m/s", "coordinate speed from the IK motion"),
    ("states.sto", "/forceset/<muscle>/activation", "-", "muscle activation (model default for muscles not solved)"),
    ("states.sto", "/forceset/<muscle>/normalized_tendon_force", "-",
     "tendon force / F0 of the DeGrooteFregly2016Muscle of model.osim (model default for muscles not solved)"),
    ("controls.sto", "/forceset/reserve_<coordinate>", "N m or N",
     "control of the coordinate's reserve actuator (optimal force 1): its generalised force in forces.sto"),
    ("controls.sto", "/forceset/<muscle>", "-", "muscle excitation"),
    ("forces.sto", "reserve_<coordinate>", "N m or N",
     "generalised force of the reserve: the solution's reserve on a solved DOF, else ID - sum(r F); the file's "
     "other columns, one per muscle of model.osim named as the muscle, hold its tendon force (N, 0 for muscles "
     "not solved), as in OpenSim's static optimisation output"),
    # keys
    ("muscle_groups.csv", "group", "-", "group abbreviation used in share_<G>_pct"),
    ("muscle_groups.csv", "name", "-", "full name of the group"),
    ("muscle_groups.csv", "dof", "-", "degree of freedom (without side suffix) the group acts about"),
    ("muscle_groups.csv", "moment_arm_sign", "-", "sign of the moment arm that puts a muscle in the group"),
    ("data_dictionary.csv", "file", "-", "tables holding the column"),
    ("muscle_groups.csv, data_dictionary.csv", "column", "-",
     "a column name: the results column of the group's share (muscle_groups.csv), the column described "
     "(data_dictionary.csv; <...> stands for a family)"),
    ("data_dictionary.csv", "unit", "-", "unit of the values"),
    ("data_dictionary.csv", "description", "-", "what the column holds"),
    # sensitivities of the rates to the muscle parameters (musclemetab metabolics --sensitivity)
    (_SENS, "solution", "-", "the solution folder (its name) whose rates the row's sensitivity is of"),
    (_SENS, "parameter_rank", "-", "rank of the parameter by |d_rate_d_log_p| within its solution, model and rate "
     "(1 = moves the rate most)"),
    (_SENS, "parameter", "-", "muscle parameter: F0 (maximal isometric force), lMo (optimal fiber length), lTs "
     "(tendon slack length), kT (tendon stiffness), kPE, s0, sM (passive force-length), vmax (maximal contraction "
     "velocity), alpha0 (pennation angle at optimal fiber length)"),
    (_SENS, "parameter_value", "SI", "the parameter's value in the solve (N, m, -, lMo/s or rad)"),
    (_SENS, "rate", "-", "the reported rate: whole_body (whole_body_W_per_kg) or a muscle's name (its muscle_W)"),
    (_SENS, "rate_value", "W/kg or W", "the rate at the optimum (W/kg for whole_body, W for a muscle)"),
    (_SENS, "d_rate_d_log_p", "W/kg or W", "derivative of the rate per log of the parameter, p dR/dp, at the optimum: "
     "the implicit-function theorem on the KKT system with the active set fixed, plus the rate formula's own "
     "dependence on the parameter (docs/uncertainty.md, Sensitivities)"),
    (_SENS, "change_per_1pct", "W/kg or W", "d_rate_d_log_p / 100: the rate's change when the parameter grows by 1 %"),
    (_SENS, "relative_change_per_1pct", "-", "change_per_1pct / rate_value: the rate's relative change per 1 % of "
     "the parameter (empty where the rate is 0)"),
    # marker errors of scaling and inverse kinematics (musclemetab prepare, a study from markers)
    ("ik_marker_errors.csv", "rms_m", "m", "RMS marker error of the IK frame (OpenSim's InverseKinematicsTool)"),
    ("ik_marker_errors.csv", "max_m", "m", "largest marker error of the IK frame"),
    ("ik_marker_errors.csv", "worst_marker", "-", "the marker of the frame's largest error"),
    ("ik_marker_errors.csv", "above_best_practice", "-",
     "1 when the frame's RMS exceeds 2 cm or its largest error 4 cm (OpenSim's best practice), else 0"),
    ("static_marker_errors.csv", "marker", "-", "a marker of the marker placement (scaling's static pose)"),
    ("static_marker_errors.csv", "error_m", "m",
     "distance of the scaled model's marker, in the static pose, from the experimental marker averaged over the "
     "static trial's time range (before the marker placer moves it)"),
    ("static_marker_errors.csv", "weight", "-", "the marker's weight in the marker placement"),
    # assistive devices (docs/assistance.md); results.csv: empty in the rows of unassisted trials
    (f"{_STUDY}, {_ASSIST}", "assisted_from", "-",
     "an assisted trial (<trial>_assist-<gain>, a device's torque taken off the ID moments): the unassisted "
     "trial it is compared with (the same files, no device)"),
    (f"{_STUDY}, {_ASSIST}", "assistance_gain", "-", "the factor on the device torque of the assistance profile"),
    (_STUDY, "device_positive_work_J", "J",
     "positive work of the device over the gait cycle (torque x joint angular velocity from the IK; one leg's device)"),
    (_STUDY, "device_negative_work_J", "J",
     "negative work of the device over the gait cycle (<= 0; energy it absorbs; one leg's device)"),
    (_STUDY, "device_positive_work_J_per_kg", "J/kg", "device_positive_work_J per kg of body mass"),
    (_STUDY, "device_negative_work_J_per_kg", "J/kg", "device_negative_work_J per kg of body mass"),
    (_STUDY, "device_positive_power_W_per_kg", "W/kg",
     "the device's average positive power over the gait cycle, both legs per kg of body mass (counted as "
     "whole_body_W_per_kg counts the legs)"),
    (_STUDY, "device_negative_power_W_per_kg", "W/kg",
     "the device's average negative power over the gait cycle (<= 0), both legs per kg of body mass"),
    (_STUDY, "metabolic_saving_W_per_kg", "W/kg",
     "whole_body_W_per_kg of the unassisted trial less that of the assisted trial (positive: the device saves "
     "metabolic energy)"),
    (_STUDY, "metabolic_saving_pct", "%", "metabolic_saving_W_per_kg in % of the unassisted whole_body_W_per_kg"),
    (_STUDY, "saving_per_positive_work", "-",
     "metabolic_saving_W_per_kg / device_positive_power_W_per_kg: metabolic energy saved per joule of positive "
     "device work"),
    (_STUDY, "augmentation_factor_W_per_kg", "W/kg",
     "(device_positive_power_W_per_kg - |device_negative_power_W_per_kg|) / 0.41, the augmentation factor of "
     "Mooney, Rouse & Herr 2014 without a carried mass"),
    (_ASSIST, "level", "-", "what the row's part is: leg (the leg's muscles), phase (stance, swing), group (a muscle "
     "function group of muscle_groups.csv, or other) or muscle"),
    (_ASSIST, "part", "-", "the leg, phase, group or muscle of the row"),
    (_ASSIST, "unassisted_J", "J", "the part's metabolic energy over the gait cycle in the unassisted trial (one leg, "
     "no basal heat; the legs' mean for legs 'r + l')"),
    (_ASSIST, "assisted_J", "J", "the part's metabolic energy over the gait cycle in the assisted trial (as "
     "unassisted_J)"),
    (_ASSIST, "change_J", "J", "assisted_J - unassisted_J (negative: the device saves)"),
    (_ASSIST, "change_pct", "%", "change_J in % of unassisted_J"),
)


def data_dictionary_table():
    """:data:`DATA_DICTIONARY` as a pandas table (``file``, ``column``, ``unit``, ``description``)."""
    import pandas as pd

    return pd.DataFrame(list(DATA_DICTIONARY), columns=["file", "column", "unit", "description"])


def describe(column: str) -> str | None:
    """The description of a column (families matched: ``share_PF_pct`` -> ``share_<G>_pct``)."""
    import re

    for _, col, unit, text in DATA_DICTIONARY:
        pattern = "^" + re.sub(r"<[^>]+>", "[^/]+", re.escape(col).replace(r"\<", "<").replace(r"\>", ">")) + "$"
        if col == column or re.match(pattern, column):
            return f"{text} ({unit})" if unit != "-" else text
    return None


def write_data_dictionary(path: str | os.PathLike):
    """Write the data dictionary as CSV (atomically); returns the path."""
    from .io.atomic import atomic_path

    with atomic_path(path) as tmp:
        data_dictionary_table().to_csv(tmp, index=False)
    return path


def data_dictionary_markdown() -> str:
    """The data dictionary as the Markdown page ``docs/data_dictionary.md``."""
    lines = [
        "# Data dictionary",
        "",
        "Every column of every table musclemetab writes: file, column, unit and meaning. The same table is",
        "written beside each study's results as `data_dictionary.csv`, from `musclemetab.datadict` (the one",
        "source; this page is rendered from it by `python -m musclemetab.datadict`). `<...>` stands for a",
        "family of columns. One leg means the simulated leg's muscles; whole body means both legs (twice the",
        "simulated leg) per kg of body mass; no basal means without any basal heat. One name has one meaning",
        "in every file: `whole_body_...` is both legs with the basal heat the name states, `leg_muscles_...`",
        "one leg's muscles without basal heat, `muscle_...` one muscle without basal heat; a file of one leg",
        "never holds a whole-body figure. The report reads the tables of earlier releases (`mean_W_per_kg`,",
        "`mean_W_per_kg_no_basal`, `one_leg_mean_W`; per muscle `mean_W`, `mean_W_per_kg`) through the",
        "mapping of `musclemetab.report.folder` ([report.md](report.md)).",
        "",
        "| file | column | unit | description |",
        "| --- | --- | --- | --- |",
    ]
    for f, c, u, d in DATA_DICTIONARY:
        lines.append(f"| {f} | `{c}` | {u} | {d} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover
    print(data_dictionary_markdown(), end="")
