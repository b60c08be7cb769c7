"""The quality report as a person reads it: an HTML page and a PDF (matplotlib), both with the
requirements table, the stability series and the flat field. matplotlib is imported only here
(the ``reports`` extra)."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.exports.percentiles import percentiles
from thermcap.recorder.install_hint import install_command
from thermcap.recorder.reports.quality import QualityReport

__all__ = ["write_inspection_report", "write_quality_report"]

_COLOURS = {"pass": "#1a7f37", "fail": "#cf222e", "not measurable": "#6e7781"}


def _figures(rep: QualityReport) -> list[Any]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - the report extra
        raise ThermcapError(f"the quality report's PDF and plots need matplotlib ({install_command('reports')})") \
            from exc
    figs = []
    if rep.series["t_s"]:
        fig, ax = plt.subplots(figsize=(7, 3))
        ax.plot(rep.series["t_s"], rep.series["mean_c"], ".", ms=2, color="#0969da")
        ax.set_xlabel("time since the first frame (s)")
        ax.set_ylabel("mean of the flat field (°C)")
        ax.set_title(f"Temporal stability: {rep.flat_source} frames")
        fig.tight_layout()
        figs.append(fig)
    if rep.flat_mean is not None:
        fig, ax = plt.subplots(figsize=(7, 4.2))
        im = ax.imshow(rep.flat_mean, cmap="inferno")
        fig.colorbar(im, ax=ax, label="counts (time average)")
        ax.set_title("FPA uniformity: the time-averaged flat field")
        ax.set_axis_off()
        fig.tight_layout()
        figs.append(fig)
    return figs


def _table_rows(rep: QualityReport) -> list[list[str]]:
    rows = []
    for m in rep.measurements:
        value = "—" if m.value is None else f"{m.value:g} {m.unit}"
        rows.append([f"{m.requirement} (ICD {m.icd})", value, m.limit, m.verdict, m.method])
    return rows


def _versions(rep: QualityReport) -> str:
    return ", ".join(f"v{v}" for v in rep.model_versions)


def _html(rep: QualityReport, images: list[bytes]) -> str:
    head = ("<!doctype html><html lang=en><meta charset=utf-8><title>ICD section 5 quality report: "
            f"{html.escape(rep.session_id)}</title><style>body{{font:14px system-ui;margin:2em;max-width:70em}}"
            "table{border-collapse:collapse}td,th{border:1px solid #d0d7de;padding:.35em .6em;text-align:left;"
            "vertical-align:top}th{background:#f6f8fa}</style>")
    overall = "pass" if all(m.passed is not False for m in rep.measurements) else "fail"
    body = [f"<h1>ICD section 5 quality report</h1><p>Session <b>{html.escape(rep.session_id)}</b>: {rep.frames} "
            f"frames, {rep.flat_frames} of them flat ({html.escape(rep.flat_source)})"
            + (f", blackbody at {rep.blackbody_c:g} °C" if rep.blackbody_c is not None else "")
            + f"; temperatures from radiometric model version {_versions(rep)}"
            + f". Overall: <b style='color:{_COLOURS[overall]}'>{overall}</b> (not measurable counts as neither).</p>",
            "<table><tr><th>requirement</th><th>measured</th><th>limit</th><th>verdict</th><th>how</th></tr>"]
    for row in _table_rows(rep):
        colour = _COLOURS[row[3]]
        body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" if i != 3 else
                                     f"<td style='color:{colour}'><b>{html.escape(c)}</b></td>"
                                     for i, c in enumerate(row)) + "</tr>")
    body.append("</table>")
    for png in images:
        data = base64.b64encode(png).decode()
        body.append(f"<p><img alt='' style='max-width:100%' src='data:image/png;base64,{data}'>")
    return head + "".join(body) + "</html>\n"


def write_quality_report(rep: QualityReport, out_dir: Path) -> dict[str, Path]:
    """``quality.html``, ``quality.pdf`` and ``quality.json`` in ``out_dir``."""
    import json

    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    out_dir.mkdir(parents=True, exist_ok=True)
    figs = _figures(rep)
    images = []
    for fig in figs:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        images.append(buf.getvalue())
    paths = {"html": out_dir / "quality.html", "pdf": out_dir / "quality.pdf", "json": out_dir / "quality.json"}
    paths["html"].write_text(_html(rep, images))
    paths["json"].write_text(json.dumps(rep.to_dict(), indent=2) + "\n")
    with PdfPages(paths["pdf"]) as pdf:
        page = plt.figure(figsize=(8.27, 11.69))  # A4
        page.text(0.06, 0.95, "ICD section 5 quality report", fontsize=16, weight="bold")
        page.text(0.06, 0.92, f"session {rep.session_id}: {rep.frames} frames, {rep.flat_frames} flat "
                              f"({rep.flat_source})" + (f", blackbody {rep.blackbody_c:g} °C"
                                                        if rep.blackbody_c is not None else "")
                              + f"; radiometric model version {_versions(rep)}", fontsize=9)
        rows = _table_rows(rep)
        table = page.add_axes((0.04, 0.35, 0.92, 0.54))
        table.set_axis_off()
        cells = [["\n".join(_wrap(r[0], 22)), r[1], "\n".join(_wrap(r[2], 16)), r[3], "\n".join(_wrap(r[4], 46))]
                 for r in rows]
        t = table.table(cellText=cells, colLabels=["requirement", "measured", "limit", "verdict", "how"],
                        loc="upper left", colWidths=[0.2, 0.13, 0.15, 0.12, 0.4], cellLoc="left")
        t.auto_set_font_size(False)
        t.set_fontsize(7)
        for (r, c), cell in t.get_celld().items():
            cell.set_height(0.075 if r else 0.03)
            if r and c == 3:
                cell.get_text().set_color(_COLOURS[rows[r - 1][3]])
        pdf.savefig(page)
        plt.close(page)
        for fig in figs:
            pdf.savefig(fig)
            plt.close(fig)
    return paths


def _wrap(text: str, width: int) -> list[str]:
    import textwrap

    return textwrap.wrap(text, width) or [""]


def write_inspection_report(rep: Any, out_dir: Path) -> dict[str, Path]:
    """``inspection.json`` (what ``report verify`` recomputes) and ``inspection.pdf``: a summary
    page, a page per finding (the frame with a colour bar and the box), and the provenance."""
    import hashlib
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.patches import Rectangle

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"json": out_dir / "inspection.json", "pdf": out_dir / "inspection.pdf"}
    data = (json.dumps(rep.to_dict(), indent=2) + "\n").encode()
    paths["json"].write_bytes(data)
    sha = hashlib.sha256(data).hexdigest()
    meta = {"Title": f"Inspection report: {rep.session_id}", "Creator": "thermcap report inspection",
            "Keywords": f"thermcap-inspection json-sha256={sha}"}
    with PdfPages(paths["pdf"], metadata=meta) as pdf:
        page = plt.figure(figsize=(8.27, 11.69))
        page.text(0.06, 0.95, "Inspection report", fontsize=16, weight="bold")
        page.text(0.06, 0.92, f"session {rep.session_id}: {len(rep.findings)} findings", fontsize=9)
        if rep.findings:
            ax = page.add_axes((0.04, 0.45, 0.92, 0.44))
            ax.set_axis_off()
            cells = [[str(i + 1), f.target_id, f.classification or "", f"{f.frame}", f.time[:23], f"{f.max_c:.2f}",
                      f"{f.delta_t_c:+.2f}", f"v{f.model_version}"] for i, f in enumerate(rep.findings)]
            t = ax.table(cellText=cells, colLabels=["#", "target", "class", "frame", "time (UTC)", "max °C", "ΔT °C",
                                                    "model"], loc="upper left", cellLoc="left")
            t.auto_set_font_size(False)
            t.set_fontsize(7)
        else:
            page.text(0.06, 0.85, "No target was detected in this session.", fontsize=10)
        if rep.events:
            page.text(0.06, 0.40, "Events: " + "; ".join(f"{e['kind']} {e['start'][11:19]}-{e['end'][11:19]}"
                                                          for e in rep.events[:12]), fontsize=7, wrap=True)
        pdf.savefig(page)
        plt.close(page)
        for i, f in enumerate(rep.findings):
            fig, ax = plt.subplots(figsize=(8.27, 6.5))
            temps = rep.images[f.frame]
            lo, hi = percentiles(temps, (0.5, 99.5))  # a dead or hot pixel sets no scale
            im = ax.imshow(temps, cmap="inferno", vmin=lo, vmax=max(hi, f.max_c))
            x0, y0, x1, y1 = f.box
            ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0 + 1, y1 - y0 + 1, fill=False, ec="#00e5ff", lw=1.5))
            fig.colorbar(im, ax=ax, label="°C")
            ax.set_axis_off()
            where = (f"{f.position['latitude']:.6f}, {f.position['longitude']:.6f}"
                     if f.position and "latitude" in f.position else "not recorded")
            ax.set_title(f"Finding {i + 1}: {f.target_id} ({f.classification or 'unclassified'}), frame {f.frame}\n"
                         f"max {f.max_c:.2f} °C, reference {f.reference_c:.2f} °C, ΔT {f.delta_t_c:+.2f} °C; "
                         f"{f.time}; position {where}\nmodel version {f.model_version}; frame sha256 "
                         f"{f.frame_sha256[:16]}…", fontsize=8)
            fig.tight_layout()
            pdf.savefig(fig)
            plt.close(fig)
        page = plt.figure(figsize=(8.27, 11.69))
        page.text(0.06, 0.95, "Provenance", fontsize=14, weight="bold")
        lines = [f"session: {rep.session_id}", f"thermcap {rep.provenance.get('thermcap')}, generated "
                 f"{rep.provenance.get('generated_at')}", f"reference temperature: {rep.provenance.get('reference')}",
                 f"JSON twin: {paths['json'].name}, sha256 {sha}", "frames (index: sha256 of the stored counts):"]
        lines += [f"  {f.frame}: {f.frame_sha256}" for f in rep.findings]
        lines += ["Every number above is recomputed from the archive by:",
                  f"  thermcap report verify {paths['pdf'].name}"]
        for k, line in enumerate(lines[:70]):
            page.text(0.06, 0.91 - k * 0.0125, line, fontsize=7, family="monospace")
        pdf.savefig(page)
        plt.close(page)
    return paths
