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
