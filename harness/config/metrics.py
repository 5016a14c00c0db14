"""The unit of every run metric (`harness.loop.metrics.compute_metrics`), written once: the study's metric
names and plot labels, the bounds' units and the run summary read it."""

# metric -> unit as a label shows it (status/message are row fields, not metrics)
METRIC_UNITS = {
    "e1_rms": "m", "e1_max": "m", "e2_rms": "m", "e2_max": "m", "e2_plant_rms": "m", "e2_plant_max": "m",
    "deN_rms": "mixed: m/s, 1/(m s)", "beta_min": "-", "ya_max": "-", "e1_final": "m", "e2_final": "m",
    "range_violation": "m or rad", "mujoco_warnings": "count", "sim_time_reached": "s", "wall_time": "s",
    "realtime_factor": "x real time", "contact_force_peak": "N", "contact_force_rms": "N",
    "penetration_max": "m", "contact_time": "s", "body_contact_time": "s", "force_tracking_rms": "N",
}
METRIC_NAMES = tuple(METRIC_UNITS)


def value_unit(metric: str) -> str:
    """The unit written after a value of `metric` ("0.0012 m"): its unit symbol; "" for a dimensionless
    number ("-"), a count, or a unit that is not one symbol ("m or rad", "mixed: ...")."""
    unit = METRIC_UNITS[metric]
    return "" if unit in ("-", "count") or " " in unit else unit


__all__ = ["METRIC_NAMES", "METRIC_UNITS", "value_unit"]
