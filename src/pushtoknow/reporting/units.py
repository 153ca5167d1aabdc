"""Display units: how each parameter is shown (the CoM in mm and I_z in g·m², as the paper
does), and the formatting every table and printout uses."""

from __future__ import annotations

# name → (factor from SI, unit)
DISPLAY_UNITS: dict[str, tuple[float, str]] = {
    "mass": (1.0, "kg"),
    "friction": (1.0, ""),
    "com_x": (1e3, "mm"),
    "com_y": (1e3, "mm"),
    "inertia": (1e3, "g·m²"),
    "mu_m": (1.0, "kg"),
}


def format_value(value: float | None, name: str, std: float | None = None) -> str:
    """'v' or 'v ± s' in the parameter's display unit (unit not written); None: '—'."""
    if value is None:
        return "—"
    f, _ = DISPLAY_UNITS[name]
    return f"{value * f:.3g}" if std is None else f"{value * f:.3g} ± {std * f:.2g}"


def format_estimate(mean: float, std: float, name: str) -> str:
    """'mean ± std unit', e.g. '12.3 ± 1.5 mm'."""
    _, unit = DISPLAY_UNITS[name]
    return f"{format_value(mean, name, std)} {unit}".strip()


def labelled(name: str) -> str:
    """'name (unit)', or the name alone for a dimensionless parameter."""
    unit = DISPLAY_UNITS[name][1]
    return f"{name} ({unit})" if unit else name
