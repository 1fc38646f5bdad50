"""Server-side SVG plots for the web view: no JavaScript, no CDN, work offline.

Each plotted point is a `<circle class="pt pt-NAME" data-x=... data-y=...>` (and its U bar a
`<line class="ubar">`), each horizontal reference line a `<line class="hline hline-KIND">`, so a
browser test counts what is drawn. Values in um; y grows upwards on the page.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from html import escape

W, H = 600, 240
LEFT, RIGHT, TOP, BOTTOM = 56, 12, 24, 30
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf")


@dataclass
class Point:
    x: float
    y_um: float
    u_um: float | None = None
    label: str = ""  # shown as the point's tooltip and data-label
    flag: bool = False  # out of control (beyond mean +- 3 s): drawn ringed, class "ooc"


@dataclass
class Series:
    name: str
    points: list[Point] = field(default_factory=list)
    stage: str | None = None  # data-stage of its points: a test reads which stage a point belongs to


@dataclass
class HLine:
    y_um: float
    label: str
    kind: str  # "tol" (tolerance), "mean", "limit" (3-sigma)
    stage: str | None = None  # the stage whose limit it is (data-stage), None for every stage


LABEL_GAP = 14  # px between two reference-line baselines: an 11 px label box is about 13 px high


def _label_ys(ys: list[float]) -> list[float]:
    """Label baselines for lines at pixel heights `ys`: each just above its line, pushed apart
    (in the order of the lines) so no two labels are closer than LABEL_GAP."""
    order = sorted(range(len(ys)), key=lambda i: ys[i])
    out = [0.0] * len(ys)
    last = None
    for i in order:
        y = ys[i] - 3
        if last is not None and y - last < LABEL_GAP:
            y = last + LABEL_GAP
        out[i] = last = y
    return out


def _fmt(v: float) -> str:
    return f"{v:.1f}"


def plot(title: str, series: list[Series], hlines: list[HLine] = (), x_labels: tuple[str, str] = ("", ""),
         y_unit: str = "um", y_floor: float | None = None) -> str:
    """An SVG scatter plot of `series` with U error bars and horizontal lines `hlines`;
    `x_labels` are printed under the left and right ends of the x axis. `y_floor`: the lowest
    value the quantity can take (0 for ISO 230-2 magnitudes): the axis never goes below it."""
    pts = [p for s in series for p in s.points]
    ys = [p.y_um for p in pts] + [p.y_um + (p.u_um or 0) for p in pts] + [p.y_um - (p.u_um or 0) for p in pts]
    ys += [h.y_um for h in hlines]
    y0, y1 = (min(ys), max(ys)) if ys else (0.0, 1.0)
    if y1 - y0 < 1e-9:
        y0, y1 = y0 - 1, y1 + 1
    pad = 0.08 * (y1 - y0)
    y0, y1 = y0 - pad, y1 + pad
    if y_floor is not None:
        y0 = max(y0, y_floor)
    xs = [p.x for p in pts]
    x0, x1 = (min(xs), max(xs)) if xs else (0.0, 1.0)
    if x1 - x0 < 1e-9:
        x0, x1 = x0 - 1, x1 + 1

    def sx(x: float) -> float:
        return LEFT + (x - x0) / (x1 - x0) * (W - LEFT - RIGHT - 10) + 5

    def sy(y: float) -> float:
        return TOP + (y1 - y) / (y1 - y0) * (H - TOP - BOTTOM)

    out = [f'<svg class="plot" role="img" aria-label="{escape(title)}" viewBox="0 0 {W} {H}" width="{W}" height="{H}" '
           f'xmlns="http://www.w3.org/2000/svg">', f'<title>{escape(title)}</title>',
           f'<rect x="{LEFT}" y="{TOP}" width="{W - LEFT - RIGHT}" height="{H - TOP - BOTTOM}" class="frame"/>']
    for k in range(5):  # y grid and tick labels
        y = y0 + (y1 - y0) * k / 4
        out.append(f'<line class="grid" x1="{LEFT}" x2="{W - RIGHT}" y1="{_fmt(sy(y))}" y2="{_fmt(sy(y))}"/>')
        out.append(f'<text class="tick" x="{LEFT - 4}" y="{_fmt(sy(y) + 4)}" text-anchor="end">{y:.2f}</text>')
    out.append(f'<text class="tick" x="{LEFT}" y="{H - 10}">{escape(x_labels[0])}</text>')
    out.append(f'<text class="tick" x="{W - RIGHT}" y="{H - 10}" text-anchor="end">{escape(x_labels[1])}</text>')
    out.append(f'<text class="tick" x="{LEFT}" y="{TOP - 8}">{escape(y_unit)}</text>')
    label_ys = _label_ys([sy(h.y_um) for h in hlines])
    for h, ly in zip(hlines, label_ys):
        y = _fmt(sy(h.y_um))
        st = f' data-stage="{escape(h.stage)}"' if h.stage else ""
        out.append(f'<line class="hline hline-{h.kind}"{st} data-y="{h.y_um:.4f}" x1="{LEFT}" x2="{W - RIGHT}" y1="{y}" '
                   f'y2="{y}"><title>{escape(h.label)}</title></line>')
        out.append(f'<text class="hlabel"{st} x="{W - RIGHT - 4}" y="{ly:.1f}" text-anchor="end">{escape(h.label)}</text>')
    for i, s in enumerate(series):
        # what is the same for every point of the series, once (a control chart draws thousands)
        colour = COLOURS[i % len(COLOURS)]
        name = escape(s.name)
        st = f' data-stage="{escape(s.stage)}"' if s.stage else ""
        unit = escape(y_unit)
        for p in s.points:
            cx, cy = _fmt(sx(p.x)), _fmt(sy(p.y_um))
            if p.u_um:
                out.append(f'<line class="ubar" stroke="{colour}" x1="{cx}" x2="{cx}" y1="{_fmt(sy(p.y_um - p.u_um))}" '
                           f'y2="{_fmt(sy(p.y_um + p.u_um))}"/>')
            u = f' data-u="{p.u_um:.4f}"' if p.u_um is not None else ""
            label = escape(p.label)
            tip = f"{name} {label} {p.y_um:.2f}" + (f" ± {p.u_um:.2f}" if p.u_um is not None else "") + f" {unit}"
            tip += " (out of control: beyond mean ± 3 s)" if p.flag else ""
            if p.flag:  # a ring around the point: seen without hovering, in any colour vision
                out.append(f'<circle class="ooc-ring" r="7" cx="{cx}" cy="{cy}"/>')
            out.append(f'<circle class="pt pt-{name}{" ooc" if p.flag else ""}" fill="{colour}" r="3.5" '
                       f'cx="{cx}" cy="{cy}" data-series="{name}"{st} data-label="{label}" '
                       f'data-y="{p.y_um:.4f}"{u}><title>{tip}</title></circle>')
    for i, s in enumerate(series):  # legend
        x = LEFT + 40 + 90 * i
        out.append(f'<circle cx="{x}" cy="{TOP - 12}" r="4" fill="{COLOURS[i % len(COLOURS)]}"/>'
                   f'<text class="legend" x="{x + 8}" y="{TOP - 8}">{escape(s.name)}</text>')
    out.append("</svg>")
    return "\n".join(out)
