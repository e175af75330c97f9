"""Pose errors and percentile summaries, as in the paper's evaluation (README, "Evaluation")."""

from __future__ import annotations

import numpy as np

#: The percentiles reported everywhere (report.json, summary tables).
PERCENTILES: tuple[int, ...] = (1, 25, 50, 75, 99)


def pose_errors(X_est: np.ndarray, X_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation error (mm) and rotation error (deg) between stacks of 4x4 poses.

    The rotation error is the angle of ``R_est^T R_true``.
    """
    X_est = np.asarray(X_est, float).reshape(-1, 4, 4)
    X_true = np.asarray(X_true, float).reshape(-1, 4, 4)
    if X_est.shape != X_true.shape:
        raise ValueError(f"pose_errors: shapes differ, {X_est.shape} vs {X_true.shape}")
    translation_mm = 1000.0 * np.linalg.norm(X_est[:, :3, 3] - X_true[:, :3, 3], axis=1)
    R_rel = np.einsum("nji,njk->nik", X_est[:, :3, :3], X_true[:, :3, :3])
    cos_angle = np.clip((np.trace(R_rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    rotation_deg = np.degrees(np.arccos(cos_angle))
    return translation_mm, rotation_deg


def percentile_summary(values: np.ndarray) -> dict[str, float]:
    """{"p1": .., "p25": .., "p50": .., "p75": .., "p99": ..} of finite ``values``."""
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {f"p{p}": float("nan") for p in PERCENTILES}
    return {f"p{p}": float(v) for p, v in zip(PERCENTILES, np.percentile(values, PERCENTILES))}


def method_report(X_est: np.ndarray, X_true: np.ndarray) -> dict[str, dict[str, float]]:
    """{"translation_mm": {...}, "rotation_deg": {...}} for one method."""
    t, r = pose_errors(X_est, X_true)
    return {"translation_mm": percentile_summary(t), "rotation_deg": percentile_summary(r)}


def format_report_table(report: dict) -> str:
    """A plain-text table of ``report["methods"]`` percentiles."""
    header = f"{'method':<16} {'metric':<15}" + "".join(f"{'p' + str(p):>9}" for p in PERCENTILES)
    lines = [header, "-" * len(header)]
    for method, metrics in report["methods"].items():
        for metric, summary in metrics.items():
            cells = "".join(f"{summary[f'p{p}']:>9.2f}" for p in PERCENTILES)
            lines.append(f"{method:<16} {metric:<15}{cells}")
    return "\n".join(lines)
