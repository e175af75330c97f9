"""The paper's reported results (SPEC §5) beside an evaluation's, point by point.

Each claim becomes figures read from the summary (:func:`summarize`'s rows: errors from
the settle time on, translation in mm) and a verdict by a rule stated with it, so that
the table in ``paper_comparison.md`` can be regenerated from any evaluation folder and
checked. A claim whose methods or sequences the evaluation did not run is "not measured".
"""

from __future__ import annotations

from dataclasses import dataclass

#: "Encoders only under simulated bias: up to 25 cm" (mm).
PAPER_ENCODER_ERROR_MM = 250.0
#: "A few mm" / "mm-level" read as at most this (mm).
MM_LEVEL_MM = 10.0
#: "Loses track" read as a 75th percentile above this (mm).
LOST_TRACK_MM = 50.0
BIASED = ("constant", "time-varying")


@dataclass(frozen=True)
class Comparison:
    """One row of the comparison table: the paper's ``claim``, ``ours`` (our figures), the
    ``verdict`` and the ``rule`` it follows from."""

    claim: str  # the paper's result, as SPEC §5 states it
    ours: str  # the figures read from the summary
    verdict: str  # matches / better / short of it / differs / not measured
    rule: str  # how the verdict follows from the figures


def _select(summary: list[dict], method: str, sequences=None, biases=None) -> list[dict]:
    return [r for r in summary if r["method"] == method and r["metric"] == "translation_mm"
            and (sequences is None or sequences(r["sequence"]))
            and (biases is None or r["bias"] in biases)]


def _case(row: dict) -> str:
    return f"{row['sequence']}/{row['bias']}"


def _by_case(rows: list[dict]) -> dict[str, dict]:
    return {_case(r): r for r in rows}


def _not_measured(claim: str, rule: str) -> Comparison:
    return Comparison(claim, "—", "not measured", rule)


def _encoder_error(summary: list[dict]) -> Comparison:
    claim = "Encoders only under simulated bias: up to 25 cm."
    rule = "largest p99 within 1.5× of 25 cm"
    rows = _select(summary, "encoders_only", biases=BIASED)
    if not rows:
        return _not_measured(claim, rule)
    worst = max(rows, key=lambda r: r["p99"])
    medians = [r["median_over_seeds"] for r in rows]
    ours = (f"up to {worst['p99'] / 10:.1f} cm (p99, {_case(worst)}); medians "
            f"{min(medians) / 10:.1f}-{max(medians) / 10:.1f} cm")
    ratio = worst["p99"] / PAPER_ENCODER_ERROR_MM
    verdict = "matches" if 1 / 1.5 <= ratio <= 1.5 else (
        "differs (larger)" if ratio > 1 else "differs (smaller)")
    return Comparison(claim, ours, verdict, rule)


def _camera_offset(summary: list[dict]) -> Comparison:
    claim = "Camera offset only: a 75th percentile of a few cm falls to a few mm."
    rule = (f"without bias, camera offset only p75 ≤ {MM_LEVEL_MM:g} mm on every sequence "
            f"where the encoders' p75 is above it")
    encoders = _by_case(_select(summary, "encoders_only", biases=("none",)))
    offset = _by_case(_select(summary, "camera_offset_only", biases=("none",)))
    cases = sorted(set(encoders) & set(offset))
    if not cases:
        return _not_measured(claim, rule)
    enc = [encoders[c]["p75"] for c in cases]
    off = [offset[c]["p75"] for c in cases]
    short = [c for c in cases if encoders[c]["p75"] > MM_LEVEL_MM
             and offset[c]["p75"] > MM_LEVEL_MM]
    ours = (f"p75 without bias: encoders only {min(enc):.0f}-{max(enc):.0f} mm, camera "
            f"offset only {min(off):.1f}-{max(off):.1f} mm ({len(cases)} sequences)")
    if short:
        ours += "; above it: " + ", ".join(
            f"{c} {offset[c]['p75']:.1f} mm" for c in short)
    verdict = "matches" if not short else f"short of it on {len(short)} of {len(cases)}"
    return Comparison(claim, ours, verdict, rule)


def _fusion_mm_level(summary: list[dict]) -> Comparison:
    claim = "Full fusion: mm-level once converged."
    rule = f"median over seeds ≤ {MM_LEVEL_MM:g} mm in every case"
    rows = _select(summary, "full_fusion")
    if not rows:
        return _not_measured(claim, rule)
    medians = sorted(r["median_over_seeds"] for r in rows)
    over = sorted((r for r in rows if r["median_over_seeds"] > MM_LEVEL_MM),
                  key=lambda r: -r["median_over_seeds"])
    worst = max(rows, key=lambda r: r["worst_seed_median"])
    ours = (f"median over seeds ≤ 5 mm in {sum(m <= 5 for m in medians)} of {len(rows)} "
            f"cases, ≤ {MM_LEVEL_MM:g} mm in {sum(m <= MM_LEVEL_MM for m in medians)}; "
            f"worst seed {worst['worst_seed_median']:.1f} mm ({_case(worst)})")
    if over:
        ours += "; above: " + ", ".join(
            f"{_case(r)} {r['median_over_seeds']:.1f}" for r in over[:4])
    verdict = "matches" if not over else f"short of it on {len(over)} of {len(rows)}"
    return Comparison(claim, ours, verdict, rule)


def _fusion_under_occlusion(summary: list[dict]) -> Comparison:
    claim = "Full fusion stays at least as accurate as encoders only under occlusion."
    rule = "full fusion p50 and p75 ≤ encoders only's in every occlusion case"

    def occluded(seq: str) -> bool:
        return "occlusion" in seq

    fusion = _by_case(_select(summary, "full_fusion", occluded))
    encoders = _by_case(_select(summary, "encoders_only", occluded))
    cases = sorted(set(fusion) & set(encoders))
    if not cases:
        return _not_measured(claim, rule)
    worse = [c for c in cases if fusion[c]["p50"] > encoders[c]["p50"]
             or fusion[c]["p75"] > encoders[c]["p75"]]
    ours = "; ".join(f"{c}: {fusion[c]['p50']:.1f} / {fusion[c]['p75']:.1f} against "
                     f"{encoders[c]['p50']:.0f} / {encoders[c]['p75']:.0f} mm" for c in cases)
    verdict = "matches" if not worse else f"short of it on {len(worse)} of {len(cases)}"
    return Comparison(claim, "p50 / p75: " + ours, verdict, rule)


def _fusion_out_of_view(summary: list[dict]) -> Comparison:
    claim = "Full fusion is pulled back to the encoders while the arm is out of view."
    rule = ("better: p50 below the encoders' by more than 20 % in every in-out-in case "
            "(the bias is held); matches: within 20 %")
    fusion = _by_case(_select(summary, "full_fusion", lambda s: s == "in-out-in"))
    encoders = _by_case(_select(summary, "encoders_only", lambda s: s == "in-out-in"))
    cases = sorted(set(fusion) & set(encoders))
    if not cases:
        return _not_measured(claim, rule)
    ratios = [fusion[c]["p50"] / max(encoders[c]["p50"], 1e-9) for c in cases]
    ours = "p50: " + "; ".join(f"{c} {fusion[c]['p50']:.0f} against "
                               f"{encoders[c]['p50']:.0f} mm" for c in cases)
    if all(r < 0.8 for r in ratios):
        verdict = "better"
    elif all(r <= 1.2 for r in ratios):
        verdict = "matches"
    else:
        verdict = "short of it"
    return Comparison(claim, ours, verdict, rule)


def _vision_only(summary: list[dict]) -> Comparison:
    claim = "Vision only loses track under occlusion, fast motion and out of view."
    rule = (f"lost: p75 > {LOST_TRACK_MM:g} mm on the occlusion, '++' and in-out-in cases; "
            f"better where it keeps track")

    def hard(seq: str) -> bool:
        return "occlusion" in seq or seq.endswith("++") or seq == "in-out-in"

    rows = _select(summary, "vision_only", hard)
    easy = _select(summary, "vision_only", lambda s: s.startswith("s-"))
    if not rows:
        return _not_measured(claim, rule)
    kept = [r for r in rows if r["p75"] <= LOST_TRACK_MM]
    ours = (f"p75 {min(r['p75'] for r in rows):.0f}-{max(r['p75'] for r in rows):.0f} mm "
            f"on {len(rows)} hard cases")
    if easy:
        ours += (f" (sinusoids: {min(r['p75'] for r in easy):.0f}-"
                 f"{max(r['p75'] for r in easy):.0f} mm)")
    if kept:
        ours += "; kept track: " + ", ".join(f"{_case(r)} {r['p75']:.0f}" for r in kept)
    verdict = "matches" if not kept else (
        "better" if len(kept) == len(rows) else f"better on {len(kept)} of {len(rows)}")
    return Comparison(claim, ours, verdict, rule)


def paper_comparison(summary: list[dict]) -> list[Comparison]:
    """The paper's five reported results, with ours, from ``summarize`` rows."""
    return [check(summary) for check in (_encoder_error, _camera_offset, _fusion_mm_level,
                                         _fusion_under_occlusion, _fusion_out_of_view,
                                         _vision_only)]


def format_paper_comparison(comparisons: list[Comparison]) -> str:
    """A markdown table: the paper's result, ours, the verdict and its rule."""
    lines = ["| the paper (SPEC §5) | ours | verdict | rule |", "|---|---|---|---|"]
    lines += [f"| {c.claim} | {c.ours} | {c.verdict} | {c.rule} |" for c in comparisons]
    return "\n".join(lines)
