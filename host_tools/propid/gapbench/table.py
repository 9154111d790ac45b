"""The bench's printed table: the tool and the baseline side by side."""

from __future__ import annotations

from propid.gapbench.census import render_census
from propid.gapbench.magnitudes import EFFECTS


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{100.0 * value:.0f} %"


def _cell(summary: dict | None, getter) -> str:
    if summary is None:
        return "n/a"
    return getter(summary)


def render(result: dict) -> str:
    tool, base = result["tool"], result["baseline"]
    rows: list[tuple[str, str, str, str]] = []

    def acc_row(label: str, get):
        n = get(base)["n"]
        rows.append((label, str(n), _cell(tool, lambda s: _pct(get(s)["accuracy"])),
                     _pct(get(base)["accuracy"])))

    for effect in EFFECTS:
        acc_row(effect, lambda s, e=effect: s["per_effect"][e])
    rows.append(("", "", "", ""))
    acc_row("single effects", lambda s: s["singles"])
    acc_row("pairs (top two)", lambda s: s["pairs"])
    acc_row("effect-free (none)", lambda s: s["none"])
    acc_row("all right (target >= 95 %)", lambda s: s["overall"])
    acc_row("  single effects, truth above the tool's floors", lambda s: s["above_floors"]["singles"])
    acc_row("  pairs, truth above the tool's floors", lambda s: s["above_floors"]["pairs"])
    acc_row("  all right, truth above the tool's floors", lambda s: s["above_floors"]["overall"])
    acc_row("  truth under the tool's reporting floors", lambda s: s["under_floor"])
    rows.append(("false-effect rate (<= 5 %)", str(base["headline_flights"]),
                 _cell(tool, lambda s: _pct(s["false_effect_rate"])), _pct(base["false_effect_rate"])))
    rows.append(("  counting ambiguous members false", "",
                 _cell(tool, lambda s: _pct(s.get("false_effect_rate_strict"))),
                 _pct(base.get("false_effect_rate_strict"))))
    rows.append(("ambiguous with the truth (not right)", "", _cell(tool, lambda s: str(s.get("ambiguous_hits"))),
                 str(base.get("ambiguous_hits"))))
    rows.append(("shrink, median best axis", "", _cell(tool, lambda s: _pct(s["shrink_median"])),
                 _pct(base["shrink_median"])))
    for label, key in (("  prediction error at 0.1 s", "shrink_pred_0.1s_median"),
                       ("  prediction error at 0.5 s", "shrink_pred_0.5s_median"),
                       ("  bound: the whole library in-sample", "shrink_library_bound_median"),
                       ("  bound, every effect flight", "shrink_library_bound_median_all")):
        rows.append((label, "", _cell(tool, lambda s, k=key: _pct(s.get(k))), _pct(base.get(key))))
    for band, stats in base["by_detectability"].items():
        rows.append((f"detectability {band}", str(stats["n"]),
                     _cell(tool, lambda s, b=band: _pct(s["by_detectability"][b]["accuracy"])),
                     _pct(stats["accuracy"])))
    for band, stats in base.get("by_pooled_detectability", {}).items():
        rows.append((f"pooled D over the flights {band}", str(stats["n"]),
                     _cell(tool, lambda s, b=band: _pct(s["by_pooled_detectability"][b]["accuracy"])),
                     _pct(stats["accuracy"])))
    acc_row("below limit (not in headline)", lambda s: s["below_limit"])
    rows.append(("failed runs", "", _cell(tool, lambda s: str(s["failed"])), str(base["failed"])))
    flights = result.get("config", {}).get("flights_per_diagnosis", 1)
    header = ("" if flights == 1 else f"{flights} flights per diagnosis", "flights", "propid gap",
              "least squares")
    widths = [max(len(r[i]) for r in rows + [header]) for i in range(4)]
    lines = ["  ".join(h.ljust(widths[i]) if i == 0 else h.rjust(widths[i])
                       for i, h in enumerate(header))]
    lines.append("  ".join("-" * w for w in widths))
    for row in rows:
        lines.append("  ".join(c.ljust(widths[i]) if i == 0 else c.rjust(widths[i])
                               for i, c in enumerate(row)))
    if tool is None:
        lines.append(f"propid gap not run: {result.get('tool_unavailable_reason')}")
    else:
        lines += ["", power_curves(tool)]
        if result.get("census") is not None:
            lines += ["", render_census(result["census"])]
    return "\n".join(lines)


def power_curves(summary: dict) -> str:
    """Single effects named right / flown per band of the detectability index D (`propid gap`):
    where each effect's detection limit lies, next to the oracle's D = 5."""
    bands = list(next(iter(summary["per_effect"].values())).get("by_detectability", {}))
    header = ["single effects right / flown, by D"] + bands
    rows = []
    for effect in EFFECTS:
        cells = summary["per_effect"][effect].get("by_detectability", {})
        rows.append([effect] + [f"{cells[b]['right']}/{cells[b]['n']}" if cells.get(b, {}).get("n") else "-"
                                for b in bands])
    widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]
    fmt = lambda r: "  ".join(c.ljust(widths[i]) if i == 0 else c.rjust(widths[i]) for i, c in enumerate(r))
    return "\n".join([fmt(header), "  ".join("-" * w for w in widths)] + [fmt(r) for r in rows])
