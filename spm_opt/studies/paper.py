"""Numbers printed in the paper, kept as printed (strings keep their printed digits).

Used only to compare the reproduction with the paper; nothing is computed from them except
the comparison itself.
"""

from __future__ import annotations

TABLE_III_LANDMARKS_MM: dict[str, tuple[str, str, str]] = {
    "A1": ("0", "0", "68.08"),
    "A2": ("-22.14", "-11.39", "63.10"),
    "A3": ("-32.44", "22.58", "60.42"),
    "A4": ("-6.69", "23.32", "66.35"),
}
"""Landmarks A_i on the skull, mm (Table III)."""

TABLE_III_PLATFORM_MM: dict[str, tuple[str, str, str]] = {
    "B1": ("0", "0", "171.33"),
    "B2": ("-55.91", "-28.77", "159.37"),
    "B3": ("-76.98", "53.58", "143.37"),
    "B4": ("-16.22", "56.55", "160.91"),
}
"""Their projections B_i on the platform sphere, mm (Table III)."""

TABLE_III_SEGMENT_S = 10.0
"""Duration of every segment, s (Table III: 0-10, 10-20, 20-30, 30-40)."""

TABLE_III_COEFFICIENTS: dict[int, dict[str, str]] = {
    1: {
        "a": "-0.029",
        "b": "0.39",
        "c": "0",
        "d": "0",
        "e": "0.014",
        "f": "-0.34",
        "g": "0",
        "h": "0",
    },
    2: {
        "a": "0.027",
        "b": "-1.30",
        "c": "16.96",
        "d": "-56.54",
        "e": "-0.005",
        "f": "-0.06",
        "g": "-2.77",
        "h": "9.23",
    },
    3: {
        "a": "-0.005",
        "b": "0.68",
        "c": "-22.59",
        "d": "207.16",
        "e": "-0.015",
        "f": "1.16",
        "g": "-27.24",
        "h": "172.40",
    },
    4: {
        "a": "-0.017",
        "b": "1.68",
        "c": "-52.58",
        "d": "507.08",
        "e": "0.006",
        "f": "-0.80",
        "g": "31.60",
        "h": "-416.08",
    },
}
"""Eq. 3 coefficients per segment, θ in degrees and t in absolute seconds:
θ1 = a t³ + b t² + c t + d, θ2 = e t³ + f t² + g t + h (Table III)."""

TABLE_IV_RMS_TORQUE_NM: tuple[str, str] = ("0.11", "0.10")
"""RMS actuator torques over the 40 s trajectory by the Lagrange method, N·m (Table IV)."""

TABLE_IV_DEVIATION_PERCENT: tuple[str, str] = ("0.29", "0.22")
"""RMS difference between the Lagrange method and SimMechanics, percent of the RMS torque."""
