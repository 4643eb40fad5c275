"""The paper's Table 2 (identified damper curve points, N, for three tyre models) and Table 3 (the
hyperbolic-tangent parameters of eq 10 fitted to them), as printed. Table 2's constant-stiffness column has
10 821.8 N as its last point, a misprint of about 1 082 N."""

from __future__ import annotations

TABLE_2_FORCE_N: dict[str, list[float]] = {
    "maxwell": [-196.8, -208.6, -186.0, -141.8, -135.6, -108.8, -80.4, -63.2, -61.6, 0.0,
                92.8, 129.6, 170.8, 228.2, 326.8, 401.0, 497.8, 618.4, 746.2, 920.4],
    "kelvin_voigt": [-439.4, -358.0, -271.0, -206.8, -173.2, -114.6, -89.0, -56.8, -39.8, 0.0,
                     67.6, 81.0, 128.0, 193.6, 293.8, 437.0, 574.4, 711.0, 889.6, 1217.4],
    "constant_stiffness": [-394.4, -293.2, -228.0, -154.2, -113.6, -58.6, -35.2, -5.4, 21.4, 0.0,
                           124.6, 123.8, 178.0, 235.4, 342.6, 483.0, 616.8, 742.2, 942.0, 10821.8],
}  # fmt: skip
"""C_a^1 … C_a^20 of each column; C_a^10 = 0 N is the point at 0 m/s."""

TABLE_3_TANH: dict[str, tuple[float, float, float, float]] = {
    "maxwell": (68.647, 937.67, 1.336, -1.203),
    "kelvin_voigt": (403.53, 620.82, 2.893, -2.418),
    "constant_stiffness": (315.94, 461.09, 3.063, -2.009),
}
"""(c_s N·s/m, κ N, μ s/m, β) of eq 10 for each column."""

MISPRINTED_POINT = ("constant_stiffness", 19)
"""Column and 0-based index of Table 2's misprint."""
