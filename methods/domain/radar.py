"""The MAROON radar's constants: the speed of light the phases are defined with and the frequency sweep of its
frames (MAROON_FORMAT.md section 2: 128 steps from 72 to 82 GHz, folder `radar_72.0_82.0_128`)."""
from __future__ import annotations

import numpy as np

C_M_PER_S = 299_792_458.0
MAROON_F_LOW_GHZ, MAROON_F_HIGH_GHZ, MAROON_N_FREQS = 72.0, 82.0, 128
MAROON_FREQS_HZ = np.linspace(MAROON_F_LOW_GHZ * 1e9, MAROON_F_HIGH_GHZ * 1e9, MAROON_N_FREQS)
MAROON_FREQS_HZ.flags.writeable = False       # shared by every caller: nobody may change it in place


def radar_folder_name(f_low_ghz: float = MAROON_F_LOW_GHZ, f_high_ghz: float = MAROON_F_HIGH_GHZ,
                      n_freqs: int = MAROON_N_FREQS) -> str:
    """MAROON's radar folder `radar_{float(f_low)}_{float(f_high)}_{int(n)}`, e.g. radar_72.0_82.0_128."""
    return f"radar_{float(f_low_ghz)}_{float(f_high_ghz)}_{int(n_freqs)}"
