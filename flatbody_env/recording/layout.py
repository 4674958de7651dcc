"""The layout of a recording: the default blueprint (views), the colours, the description text.

One layout code path for every kind of recording (free scene, env episode, agent demo).
"""

from __future__ import annotations

import numpy as np

ACTION_NAMES = ("tau1", "tau2", "tau3", "f_rho")
"""Default names of the four controls u = (τ1, τ2, τ3, f_ϱ) (see :mod:`flatbody_env.physics.equations`)."""

SCALAR_SERIES = (
    ("lambda", "λ"),
    ("mu", "μ"),
    ("rho", "ϱ"),
    ("theta", "θ"),
    ("energy", "energy H"),
    ("casimir", "|s|²"),
    ("p_theta", "p_θ"),
)
COLOR_AXES = np.array([[230, 60, 60, 255], [60, 180, 75, 255], [60, 110, 230, 255]], dtype=np.uint8)


def material_line_colors(spokes: int) -> np.ndarray:
    colors = np.tile(np.array([[200, 200, 200, 255]], dtype=np.uint8), (spokes + 2, 1))
    colors[1] = (255, 170, 0, 255)  # the fibre along e1
    colors[-1] = (120, 120, 255, 255)  # the normal
    return colors



def blueprint(rr, *, env: bool):
    import rerun.blueprint as rrb

    views = [
        rrb.TimeSeriesView(
            name="λ, μ, ϱ",
            origin="/series",
            contents=["/series/lambda", "/series/mu", "/series/rho", "/series/target/lambda", "/series/target/mu", "/series/target/rho"],
        ),
        rrb.TimeSeriesView(name="θ", origin="/series", contents=["/series/theta"]),
        rrb.TimeSeriesView(name="energy", origin="/series", contents=["/series/energy", "/series/target/energy"]),
        rrb.TimeSeriesView(
            name="|s|², p_θ, s3",
            origin="/series",
            contents=["/series/casimir", "/series/p_theta", "/series/target/s3", "/series/target/p_theta"],
        ),
        rrb.TimeSeriesView(name="G entries", origin="/series/G"),
        rrb.TimeSeriesView(name="C entries", origin="/series/C"),
    ]
    if env:
        views = [
            rrb.TimeSeriesView(name="reward terms", origin="/series/reward"),
            rrb.TimeSeriesView(name="actions", origin="/series/action"),
            rrb.TimeSeriesView(name="target", origin="/series/target"),
            *views,
        ]
    series = rrb.Tabs(*views)
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial3DView(name="body (spatial frame): R, Φ, axes of C", origin="/world"),
                rrb.Spatial3DView(name="material frame: U(θ), axes of G", origin="/material"),
                rrb.TextDocumentView(name="description", origin="/description"),
                column_shares=[3, 2, 2],
            ),
            rrb.Horizontal(
                series,
                rrb.Vertical(
                    rrb.TensorView(name="G = ΦᵀΦ", origin="/tensors/G"),
                    rrb.TensorView(name="C = Φ⁻ᵀΦ⁻¹", origin="/tensors/C"),
                ),
                column_shares=[3, 1],
            ),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="sim_time"),
        collapse_panels=True,
    )


def description_markdown(title: str, body, extra: str) -> str:
    try:
        desc = body.describe()
    except Exception:  # a duck-typed body without describe()
        desc = repr(body)
    text = f"""# {title}

A flat affinely-rigid body with thickness (paper [1], sections 3–3.4; corrections in [2]).
Body: {desc}.

**Configuration** Φ = R · diag(λ, μ, ϱ) · U(θ)⁻¹ (eqs. (23)–(24) of [1]).

* **body (spatial frame)** — the blue wireframe ellipsoid has semi-axes λ, μ, ϱ along the
  columns of R. The grey *material lines* (rim circle, spokes, normal; the orange spoke is the
  fibre along e₁) are drawn under `Transform3D(mat3x3 = Φ)`: their turning inside the ellipse is
  the material rotation U(θ), invisible in the ellipsoid itself. Arrows: principal axes of the
  Cauchy tensor C = Φ⁻ᵀΦ⁻¹ = R D⁻² Rᵀ (eigenvalues 1/λ², 1/μ², 1/ϱ²; erratum E7 of [2]).
* **material frame** — the undeformed material lines and the ellipsoid G^½(ball) = U D (ball):
  arrows are the principal axes of the Green tensor G = ΦᵀΦ = U D² Uᵀ (eq. (33) of [1]),
  the columns of U(θ); eigenvalues λ², μ², ϱ² (eq. (35)).
* **tensors** — G and C as 3×3 matrices; their six independent entries (11, 22, 33, 12, 13, 23)
  are also plotted as time series.
* **time series** — λ, μ, ϱ (and the target, for env episodes), θ, the energy H (eq. (41) of [1]),
  the Casimir |s|² and p_θ (conserved for J₁ = J₂), and for env episodes reward terms and actions
  u = (τ₁, τ₂, τ₃, f_ϱ).

Timelines: `step` (integration/env step) and `sim_time` (simulated time).
"""
    if extra:
        text += "\n" + extra.strip() + "\n"
    return text

