"""PSNR against frame time, one panel per scene, from compare.py's results.json: an SVG written by hand (no plotting
library in the peers' venv), and a markdown table of the same points.

    python3 bench/peers/fidelity_plot.py target/peers/final/results.json target/peers/final/fidelity.svg

Each tool is a point: voxstream's variants (compare.py's `voxstream-...` names) in one colour per mode, VTK in black.
The dashed line is 40 dB; the dotted one VTK's PSNR + 3 dB (the issue's floor for a default).
"""
import json
import sys
from pathlib import Path

PANEL_W, PANEL_H, MARGIN = 300, 220, 46
COLOURS = {"vtk": "#000000", "pre-adapt": "#7b3294", "pre": "#d95f02", "adapt": "#1b9e77", "fixed": "#386cb0"}


def mode(tool: str) -> str:
    if tool.startswith("vtk"):
        return "vtk"
    parts = set(tool.split("-")[1:])
    pre = "pre" in parts
    # Volumes take the adaptive step unless `faithful` (the default since 2026-12-06).
    adapt = "faithful" not in parts
    return "pre-adapt" if pre and adapt else "pre" if pre else "adapt" if adapt else "fixed"


def panel(name: str, row: dict, x0: float, y0: float) -> list:
    points = [(tool, r["median_s"] * 1000, r["psnr"]) for tool, r in row.items()]
    t_max = max(p[1] for p in points) * 1.1
    lo = min(min(p[2] for p in points), 40.0) - 2
    hi = max(p[2] for p in points) + 2
    sx = lambda t: x0 + MARGIN + (PANEL_W - MARGIN - 10) * t / t_max
    sy = lambda db: y0 + PANEL_H - MARGIN + -(PANEL_H - MARGIN - 20) * (db - lo) / (hi - lo)
    out = [f'<text x="{x0 + PANEL_W / 2}" y="{y0 + 14}" text-anchor="middle" font-weight="bold">{name}</text>',
           f'<line x1="{sx(0)}" y1="{sy(lo)}" x2="{sx(t_max)}" y2="{sy(lo)}" stroke="#888"/>',
           f'<line x1="{sx(0)}" y1="{sy(lo)}" x2="{sx(0)}" y2="{sy(hi)}" stroke="#888"/>',
           f'<text x="{x0 + PANEL_W / 2}" y="{y0 + PANEL_H - 14}" text-anchor="middle">warm frame, ms</text>',
           f'<text x="{x0 + 10}" y="{y0 + PANEL_H / 2}" transform="rotate(-90 {x0 + 10} {y0 + PANEL_H / 2})" '
           f'text-anchor="middle">PSNR, dB</text>']
    for k in range(5):
        t = t_max * k / 4
        out.append(f'<text x="{sx(t)}" y="{sy(lo) + 14}" text-anchor="middle" font-size="9">{t:.0f}</text>')
        db = lo + (hi - lo) * k / 4
        out.append(f'<text x="{sx(0) - 4}" y="{sy(db) + 3}" text-anchor="end" font-size="9">{db:.0f}</text>')
    floors = [(40.0, "4 3")]
    vtk = [p for p in points if p[0].startswith("vtk")]
    if vtk:
        floors.append((vtk[0][2] + 3, "1 3"))
    for db, dash in floors:
        if lo <= db <= hi:
            out.append(f'<line x1="{sx(0)}" y1="{sy(db)}" x2="{sx(t_max)}" y2="{sy(db)}" stroke="#999" '
                       f'stroke-dasharray="{dash}"/>')
    for tool, t, db in points:
        colour = COLOURS[mode(tool)]
        label = tool.replace("voxstream-", "").replace("voxstream", "default").replace("vtk-fixed-point", "VTK")
        out.append(f'<circle cx="{sx(t):.1f}" cy="{sy(db):.1f}" r="3.5" fill="{colour}"/>')
        out.append(f'<text x="{sx(t) + 5:.1f}" y="{sy(db) - 4:.1f}" font-size="8" fill="{colour}">{label}</text>')
    return out


def main(results_path: Path, svg_path: Path):
    results = json.loads(results_path.read_text())
    rows = list(results.items())
    columns = 3
    width = PANEL_W * columns
    height = PANEL_H * ((len(rows) + columns - 1) // columns) + 30
    body = []
    for i, (key, row) in enumerate(rows):
        body += panel(key, row, PANEL_W * (i % columns), 30 + PANEL_H * (i // columns))
    legend = " · ".join(f'<tspan fill="{c}">{m}</tspan>' for m, c in COLOURS.items())
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" '
           f'font-size="11"><rect width="100%" height="100%" fill="white"/>',
           f'<text x="10" y="18">PSNR to the brute-force reference against warm frame time (512², 2 cores): '
           f'{legend}; dashed 40 dB, dotted VTK + 3 dB</text>', *body, "</svg>"]
    svg_path.write_text("\n".join(svg) + "\n")
    print("| scene | tool | frame (median) | PSNR | time ÷ VTK's |")
    print("|---|---|---:|---:|---:|")
    for key, row in rows:
        vtk = next((r["median_s"] for t, r in row.items() if t.startswith("vtk-fixed")), None)
        for tool, r in sorted(row.items(), key=lambda item: item[1]["median_s"]):
            ratio = f"{r['median_s'] / vtk:.2f}×" if vtk else ""
            print(f"| {key} | {tool} | {r['median_s'] * 1000:.0f} ms | {r['psnr']:.1f} dB | {ratio} |")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: fidelity_plot.py RESULTS_JSON OUT_SVG")
    main(Path(sys.argv[1]), Path(sys.argv[2]))
