"""Published figures used as reference data (with their sources).

Only numbers printed in the seed papers live here; nothing computed by flexctrl.
"""

from __future__ import annotations

# Subedi, Tyapin, Hovland (2021), Robotics 10, 70, Table 3: eigenfrequencies (Hz) of
# links 1-3 (two modes each) at q2 = q3 = 0 with payload 0 kg and 2 kg.
SUBEDI_TABLE3_HZ: dict[float, tuple[tuple[float, float], ...]] = {
    0.0: ((2.56, 17.38), (4.34, 28.74), (14.17, 88.82)),
    2.0: ((2.02, 15.03), (2.67, 18.82), (4.90, 63.97)),
}
# Table 3 prints two decimals: its own rounding is +-0.005 Hz.
SUBEDI_TABLE3_ROUNDING_HZ = 0.005

# Subedi et al. (2021), Table 1: link dimensions (m) of the hollow rectangular aluminium
# beams: (length, width, height, wall thickness) for links 1-3.
SUBEDI_TABLE1_M: tuple[tuple[float, float, float, float], ...] = (
    (1.5, 50e-3, 50e-3, 4e-3),
    (1.5, 40e-3, 40e-3, 3e-3),
    (1.5, 30e-3, 30e-3, 2.5e-3),
)

# Subedi et al. (2021), Table 2: simulation parameters, per link (l m, rho kg/m, m_l kg,
# EI N m^2, J_l kg m^2) and per hub (J_h kg m^2); J_p (kg m^2) and g_v (m/s^2).  The hub
# masses m_h2, m_h3 are not printed (flexctrl.modal.identify fits them to Table 3).
SUBEDI_TABLE2_LINKS: tuple[dict[str, float], ...] = (
    {"length": 1.5, "mass_per_length": 1.9872, "mass": 2.9808, "EI": 1.8045e4, "inertia": 0.5589},
    {"length": 1.5, "mass_per_length": 1.1988, "mass": 1.7982, "EI": 7.0361e3, "inertia": 0.3372},
    {"length": 1.5, "mass_per_length": 0.7425, "mass": 1.1138, "EI": 2.4114e3, "inertia": 0.2088},
)
SUBEDI_TABLE2_HUB_INERTIA: tuple[float, ...] = (0.0022, 6.631e-4, 7.0100e-5)
SUBEDI_TABLE2_PAYLOAD_INERTIA = 3.2e-4
SUBEDI_TABLE2_GRAVITY = (0.0, -9.81)

# Subedi et al. (2021), Section 4.4 (Fig 14): the frequency components (Hz) of the tip
# deflection w_ie of links 1-3 (damped free vibration under gravity, 2 kg, q_f31(0) = 0.1 m,
# q_f32(0) = 0.002 m), from N_s = 2000 samples at 1 ms, as printed.
SUBEDI_FIG14_PEAKS_HZ: tuple[tuple[float, float], ...] = (
    (0.4883, 1.465),
    (0.883, 42.48),
    (0.9766, 42.48),
)
SUBEDI_FIG14_SAMPLES = 2000
SUBEDI_FIG14_DT_S = 1e-3
