"""The HTML report (validation/out/report.html): verdict tables, intersection results,
adaptive sampling, error-against-time plots and the efficiency table."""
import html
import os

import numpy as np

from cases import BATCHES


REF_COLOURS = {"native": "#d62728", "embree": "#1f77b4", "embree3": "#1f77b4", "embree4": "#17becf", "mitsuba": "#2ca02c", "mitsuba_ptracer": "#98df8a", "cycles": "#ff7f0e", "povray": "#9467bd"}


def svg_curves(series, width=360, height=240):
    """A log-log plot of relMSE against seconds, as inline SVG."""
    pts = [(p["seconds"], p["rel_mse"]) for _, c, _ in series for p in c if p["seconds"] > 0 and p["rel_mse"] > 0]
    if not pts:
        return ""
    lx = [np.log10(t) for t, _ in pts]
    ly = [np.log10(e) for _, e in pts]
    x0, x1, y0, y1 = min(lx) - 0.1, max(lx) + 0.1, min(ly) - 0.1, max(ly) + 0.1
    px = lambda v: 40 + (np.log10(v) - x0) / (x1 - x0) * (width - 50)
    py = lambda v: height - 30 - (np.log10(v) - y0) / (y1 - y0) * (height - 40)
    parts = [f'<svg width="{width}" height="{height}" class="curve"><rect x="40" y="10" width="{width-50}" height="{height-40}" fill="none" stroke="#999"/>',
             f'<text x="{width/2 - 40}" y="{height-5}" font-size="11">sample time (s, log)</text><text x="2" y="20" font-size="11">relMSE</text>',
             f'<text x="40" y="{height-18}" font-size="9">{10**x0:.2g}</text><text x="{width-40}" y="{height-18}" font-size="9">{10**x1:.2g}</text>',
             f'<text x="2" y="{height-30}" font-size="9">{10**y0:.1e}</text><text x="2" y="40" font-size="9">{10**y1:.1e}</text>']
    for i, (name, c, colour) in enumerate(series):
        line = " ".join(f"{px(p['seconds']):.1f},{py(p['rel_mse']):.1f}" for p in sorted(c, key=lambda p: p["seconds"]) if p["seconds"] > 0 and p["rel_mse"] > 0)
        parts.append(f'<polyline points="{line}" fill="none" stroke="{colour}" stroke-width="2"/>')
        parts.append(f'<text x="{width-110}" y="{25+14*i}" font-size="11" fill="{colour}">{html.escape(name)}</text>')
    parts.append("</svg>")
    return "".join(parts)


def region_cell(r):
    """The region whose mean differs most, as ours ± CI vs the reference's, in a tooltip-free
    compact form; every region is in summary.json."""
    regs = r.get("regions") or []
    if not regs:
        return "-"
    g = max(regs, key=lambda q: abs(q["z"]))
    return (f"{len(regs)} regions, worst z {g['z']:+.2f}:<br>{g['mean']:.5g}&plusmn;{g['ci95']:.2g} vs "
            f"{g['reference_mean']:.5g}&plusmn;{g['reference_ci95']:.2g}")


def efficiency(point):
    """1 / (relMSE x seconds) of a curve's point; none where the error is 0 (a black image, or
    one a renderer computes exactly) or the time is."""
    work = point["rel_mse"] * point["seconds"]
    return f"{1.0 / work:.3g}" if work > 0 else "–"


def write_report(out, summary):
    esc = html.escape
    rad = [r for r in summary["results"] if r["kind"] in ("radiance", "adaptive")]
    ada = [r for r in summary["results"] if r["kind"] == "adaptive"]
    bias = [r for r in summary["results"] if r["kind"] == "adaptive_bias"]
    geo = [r for r in summary["results"] if r["kind"] == "geometry"]
    rows = []
    for r in rad:
        title = esc(r["case"] + (f" ({r['label']})" if r.get("label") else ""))
        if "refused" in r:
            rows.append(f"<tr data-result><td>{title}</td><td>-</td><td>{esc(r['reference'])}</td><td class='refused' colspan='11'>reference refuses: {esc(r['refused'])}</td></tr>")
            continue
        c = r["case"]
        img = r.get("image", r["backend"])
        flip = f"{r['flip']:.4f}" if r.get("flip") is not None else "n/a"
        ok = r.get("verdict_passed", r["passed"])
        verdict, cls = ("pass", "pass") if ok else (("biased (expected)", "refused") if r.get("informational") else ("FAIL", "fail"))
        rows.append(
            f"<tr data-result><td>{title}</td><td>{r['backend']}</td><td>{esc(r['reference_renderer'])}</td><td class='{cls}'>{verdict}</td>"
            f"<td>{100 * r['pass_fraction']:.2f} %</td><td>{r['global_z']:+.2f}</td><td>{100 * (r['relative_mean_difference'] or 0):+.3f} %</td><td>{r['rel_mse']:.2e}</td>"
            f"<td>{r['smape']:.4f}</td><td>{flip}</td><td>{region_cell(r)}</td><td><img src='{esc(c)}/{img}.png'></td><td><img src='{esc(c)}/{r['reference']}.png'></td>"
            f"<td><img src='{esc(c)}/{img}_{r['reference']}_z.png'></td></tr>")
    grows = []
    for r in geo:
        imgs = "".join(f"<img src='{esc(r['case'])}/{esc(i)}'>" for i in r.get("images", []))
        grows.append(f"<tr data-result><td>{esc(r['case'])}</td><td>{r['backend']}</td><td>{r['reference']}</td><td class='{'pass' if r['passed'] else 'fail'}'>{'pass' if r['passed'] else 'FAIL'}</td>"
                     f"<td style='text-align:left'>{esc(r['summary'])}</td><td>{imgs}</td></tr>")
    arows = []
    for r in ada:
        a = r["adaptive_single"]
        eq = r["uniform_spp_at_equal_error"]
        arows.append(f"<tr><td>{esc(r['case'])} ({r['rule']} rule)</td><td>{r['backend']}</td><td>{r['reference']}</td><td>{a['samples_per_pixel']:.1f} / {r['spp']}</td><td>{a['rel_mse']:.2e}</td>"
                     f"<td>{'%.1f' % eq if eq else 'outside the ladder'}</td><td>{'%.0f %%' % (100 * r['samples_saved']) if r['samples_saved'] is not None else '-'}</td>"
                     f"<td>{'%.0f %%' % (100 * r['time_saved']) if r['time_saved'] is not None else '-'}</td><td><img src='{esc(r['case'])}/{r['image']}_rate.png'></td></tr>")
    for r in bias:
        b = r["bias"]
        arows.append(f"<tr data-result><td>{esc(r['case'])}</td><td>{r['backend']}</td><td>{r['reference']}</td><td colspan='5' style='text-align:left'>stopping-rule bias, {esc(r['config'])}: "
                     f"CS184 rule {100*b['cs184']['relative_bias']:+.2f} % &plusmn; {100*b['cs184']['se_relative']:.2f} % (t {b['cs184']['t']:+.1f}); "
                     f"pilot {100*b['pilot']['relative_bias']:+.2f} % &plusmn; {100*b['pilot']['se_relative']:.2f} % (t {b['pilot']['t']:+.1f}, critical {r['t_critical']:.2f})</td>"
                     f"<td class='{'pass' if r['passed'] else 'fail'}'>{'pilot unbiased: pass' if r['passed'] else 'FAIL'}</td></tr>")
    curves, eff_rows = [], []
    for case in sorted({r["case"] for r in rad if "refused" not in r and r["kind"] == "radiance"}):
        rs = [r for r in rad if r["case"] == case and "refused" not in r]
        series, fits = [], []
        for r in rs:
            if r["reference"] == rs[0]["reference"]:
                series.append((r["backend"], r["curve"], REF_COLOURS.get(r["backend"], "#333")))
                fits.append((r["backend"], r["timing"]["ours"]))
        for ref in sorted({r["reference"] for r in rs}):
            rr = next(r for r in rs if r["reference"] == ref)
            series.append((ref, rr["reference_curve"], REF_COLOURS.get(ref, "#333")))
            fits.append((ref, rr["timing"]["reference"]))
        curves.append(f"<div class='plot'><h3>{esc(case)}</h3>{svg_curves(series)}</div>")
        for (name, c, _), (_, fit) in zip(series, fits):
            if not c or not fit:
                continue
            best = max(c, key=lambda p: p["spp"])
            eff_rows.append(f"<tr><td>{esc(case)}</td><td>{name}</td><td>{1e3 * fit['fixed_seconds']:.1f}</td><td>{1e3 * fit['seconds_per_spp']:.3f}</td>"
                            f"<td>{best['spp']}</td><td>{best['median_seconds']:.3f}</td><td>{best['seconds']:.3f}</td><td>{best['rel_mse']:.2e}</td>"
                            f"<td>{efficiency(best)}</td></tr>")
        for r in rs:
            eq = r.get("equal_time_rel_mse_ratio")
            eff_rows.append(f"<tr><td>{esc(case)}</td><td>{r['backend']} ÷ {r['reference']} at equal time</td><td colspan='7'>{'%.2f at %.3f s' % (eq['ratio'], eq['seconds']) if eq else 'no overlapping times'}</td></tr>")
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>pathtracer validation ({summary['tier']})</title>
<style>body{{font-family:sans-serif}} table{{border-collapse:collapse}} td,th{{border:1px solid #999;padding:3px 6px;text-align:right}}
img{{width:128px;image-rendering:pixelated}} .pass{{background:#cfc}} .fail{{background:#fcc}} .refused{{background:#eee;text-align:left}} .plot{{display:inline-block}}</style>
<script>window.addEventListener("load", () => {{ const imgs = [...document.images];
document.body.dataset.images = imgs.length; document.body.dataset.imagesOk = imgs.filter(i => i.complete && i.naturalWidth > 0).length; }});</script></head><body>
<h1>pathtracer validation: {summary['tier']} tier</h1>
<p>{esc(summary['pathtracer'])}. References: {esc(', '.join(summary['references']))}.</p>
<h2>Light transport</h2>
<p>Verdict: per pixel-channel Welch z-test (alpha 0.01, Šidák), pass at &ge; 99.75 % of pixel-channels, plus a global test of the
image mean by batch means (ours: {BATCHES} independent renders, the reference: its independent renders; Student t, alpha 0.01).
z-map: blue z &le; -4, white 0, red z &ge; 4. FLIP: mean LDR FLIP of the tone-mapped images (report only). Regions: a 4&times;3 grid of
region means with 95 % confidence intervals (report only; all in summary.json).</p>
<table id="verdicts"><tr><th>case</th><th>backend</th><th>reference</th><th>verdict</th><th>pixels passing</th><th>global t</th><th>mean diff</th>
<th>relMSE</th><th>SMAPE</th><th>FLIP</th><th>regions</th><th>ours</th><th>reference</th><th>z-map</th></tr>
{''.join(rows)}</table>
<h2>Intersections</h2>
<p>POV-Ray: one ray through each pixel centre (ours at -s 1); ids must be identical except on silhouettes (a differently coloured
neighbour), depths equal to POV-Ray's half-float precision. Cycles: pixel averages; ids identical on interior pixels, silhouette
coverage and interior depth and normal by the per-pixel z-test. Images: ours, reference, differences (orange: silhouette, red: failure).</p>
<table id="geometry"><tr><th>case</th><th>backend</th><th>reference</th><th>verdict</th><th>what was found</th><th>images</th></tr>{''.join(grows)}</table>
<h2>Adaptive sampling</h2>
<p>One adaptive render against uniform renders at 1/8 .. 1 of the maximum: the uniform spp (and time) at the adaptive render's
relMSE, by log-log interpolation; samples saved = 1 - adaptive samples kept / uniform samples at equal error (the pilot rule also
spends its discarded pilot samples: compare its time saved). In the verdicts above, the CS184 rule's converged image is reported
but not a gate: the rule decides on the samples it keeps, so its image is biased dark by design. The bias rows run a
rare-path configuration many times with each stopping rule; the pilot rule must be unbiased, the CS184 rule's bias is reported.
Image: the rate image (samples kept per pixel).</p>
<table id="adaptive"><tr><th>case</th><th>backend</th><th>reference</th><th>spp kept / max</th><th>relMSE</th><th>uniform spp at equal error</th>
<th>samples saved</th><th>time saved</th><th>rate</th></tr>{''.join(arows)}</table>
<h2>Error against time</h2><p>Every renderer renders the spp ladder with several independent seeds per rung, each render timed on
its own inside its process (process start, scene loading and BVH build excluded). Error: the expected relMSE of one render, the
variance across the seeds / (reference&sup2; + 0.01) averaged over pixel-channels (the same reference image for every renderer).
Time: a line fixed + per-spp &middot; spp through the rungs' median timings, and the plotted time is per-spp &middot; spp: fixed
costs (thread start, buffers, Blender's scene sync) are reported, and excluded the same way for every renderer.</p>
{''.join(curves)}
<h2>Efficiency</h2><table id="efficiency"><tr><th>case</th><th>renderer</th><th>fixed (ms)</th><th>per spp (ms)</th><th>spp</th><th>median s</th><th>sample s</th><th>relMSE</th>
<th>1/(relMSE·s)</th></tr>{''.join(eff_rows)}</table>
</body></html>"""
    with open(os.path.join(out, "report.html"), "w") as f:
        f.write(doc)
