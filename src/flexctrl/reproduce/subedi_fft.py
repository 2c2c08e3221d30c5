"""Subedi et al. (2021), Fig 14: the FFT of the tip deflections (Section 4.4), and link 2's low
peak.

The paper transforms w_ie (the tip deflection of link i in its own frame, Eq 2) of the damped
free vibration, N_s = 2000 samples at 1 ms, and prints Link 1: 0.4883, 1.465 Hz; Link 2:
0.883, 42.48 Hz; Link 3: 0.9766, 42.48 Hz.  Those digits are whole multiples of
1000/2048 Hz = 0.48828 Hz (bins 1, 3, 2 and 87), the grid of a 2048-point transform: the
2000 samples were zero-padded to the next power of two (MATLAB's ``nextpow2`` idiom).
On that grid flexctrl's two strongest peaks are the printed ones to every digit except
link 2's 0.883 Hz, which is not a frequency of the grid (it falls 1.81 bins up) and
is what 0.4883 becomes with its 4 dropped; flexctrl's link-2 peak is 0.4883 Hz under every
reading tried (window, padding, mean, which coordinate, the modes, Eq 68).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flexctrl.modal.paper_data import SUBEDI_FIG14_DT_S, SUBEDI_FIG14_PEAKS_HZ, SUBEDI_FIG14_SAMPLES
from flexctrl.reproduce.drawing import figure, save
from flexctrl.reproduce.items import Item, Section
from flexctrl.reproduce.subedi_runs import Runs
from flexctrl.sim.fft_peaks import amplitude_spectrum, dominant_frequencies

N_FFT = 2048  # 2**nextpow2(2000)
RESOLUTION_HZ = 1.0 / (N_FFT * SUBEDI_FIG14_DT_S)


def tip_signals(runs: Runs, variant: str = "frozen") -> np.ndarray:
    """The paper's 2000 samples of w_1e, w_2e, w_3e (m), shape (2000, 3)."""
    traj = runs.get("free_damped", variant)
    return traj.deflections[:SUBEDI_FIG14_SAMPLES]


def peaks(signal: np.ndarray, n_fft: int | None = N_FFT) -> list[float]:
    """The two strongest spectral peaks (Hz) of ``signal`` sampled at 1 ms, ascending."""
    return sorted(dominant_frequencies(signal, SUBEDI_FIG14_DT_S, 2, n_fft=n_fft))


def on_grid(f: float) -> float:
    """Distance of ``f`` (Hz) from the nearest 2048-point bin, in bins."""
    return abs(f / RESOLUTION_HZ - round(f / RESOLUTION_HZ))


def readings(runs: Runs) -> list[tuple[str, list[list[float]]]]:
    """Every link's two peaks under the readings of Section 4.4 that could move them."""
    w = tip_signals(runs)
    traj = runs.get("free_damped")
    coords = np.column_stack([traj.coordinate(f"qf{k}1")[:SUBEDI_FIG14_SAMPLES] for k in (1, 2, 3)])
    hann = (w - w.mean(axis=0)) * np.hanning(w.shape[0])[:, None]
    cases = [
        ("w_ie, 2000 points, no padding (0.5 Hz bins)", w, None),
        ("w_ie, zero-padded to 2048 (0.488 Hz bins)", w, N_FFT),
        ("w_ie, zero-padded to 4096 (0.244 Hz bins)", w, 4096),
        ("w_ie, Hann window, 2048", hann, N_FFT),
        ("q_fi1 (first modal coordinate) instead of w_ie, 2048", coords, N_FFT),
        ("w_ie with scheduled modes, 2048", tip_signals(runs, "scheduled"), N_FFT),
        ("w_ie with Eq 68 as printed, 2048", tip_signals(runs, "eq68"), N_FFT),
    ]
    return [(name, [peaks(signal[:, k], n) for k in range(3)]) for name, signal, n in cases]


def matched(found: list[list[float]], tol: float = 0.01) -> int:
    """How many of the six printed peaks ``found`` holds to ``tol`` Hz (the printed digits)."""
    return sum(
        any(abs(f - p) <= tol for f in found[k])
        for k, row in enumerate(SUBEDI_FIG14_PEAKS_HZ)
        for p in row
    )


def fig14(runs: Runs, out_dir: Path) -> Section:
    """Fig 14: the peaks against the paper's within one bin, the figure, and link 2's low peak
    explained."""
    w = tip_signals(runs)
    t = np.arange(w.shape[0]) * SUBEDI_FIG14_DT_S
    items = []
    fig, axes = figure(3, 2, 5.2, 2.6)
    for link in range(3):
        ours = peaks(w[:, link])
        items.extend(_peak_items(link, ours, peaks(w[:, link], None)))
        _draw_link(axes, link, t, w[:, link], ours)
    printed = [f for row in SUBEDI_FIG14_PEAKS_HZ for f in row]
    off = [f for f in printed if on_grid(f) > 0.05]
    items.append(
        Item(
            "Fig 14, the paper's frequency grid",
            f"N_s = {SUBEDI_FIG14_SAMPLES} samples at 1 ms",
            f"{len(printed) - len(off)} of {len(printed)} printed peaks are multiples of "
            "1000/2048 Hz "
            f"(within 0.05 bin: {', '.join(f'{f / RESOLUTION_HZ:.2f}' for f in printed)} bins); "
            "off the grid: "
            f"{', '.join(map(str, off)) or 'none'}",
            len(off) == 1 and off[0] == SUBEDI_FIG14_PEAKS_HZ[1][0],
            "so the paper zero-padded its 2000 samples to 2048, and 0.883 is the one value that "
            "does not fit",
        )
    )
    return Section(
        "Fig 14: tip deflections and their spectra",
        _fig14_text(runs),
        items,
        [save(fig, out_dir, "fig14_fft.png")],
    )


def _peak_items(link: int, ours: list[float], ours_2000: list[float]) -> list[Item]:
    """Link ``link``'s two peaks against the paper's, each within one bin."""
    items = []
    for k, (paper, mine, mine_2000) in enumerate(zip(SUBEDI_FIG14_PEAKS_HZ[link], ours, ours_2000)):
        note = (
            f"one 2048-point bin is {RESOLUTION_HZ:.4f} Hz; without padding "
            f"{mine_2000:.2f} Hz (0.5 Hz bins)"
        )
        if link == 1 and k == 0:
            note = (
                f"0.883 Hz is {paper / RESOLUTION_HZ:.2f} bins, off the paper's own "
                "2048-point grid "
                "(bin 1 = 0.4883, bin 2 = 0.9766 Hz): read as a misprint of 0.4883 (the '4' "
                "dropped); "
                "within one bin either way (see the text)"
            )
        items.append(
            Item(
                f"Fig 14, link {link + 1}, {('first', 'second')[k]} peak",
                f"{paper} Hz",
                f"{mine:.4f} Hz",
                abs(mine - paper) <= RESOLUTION_HZ * (1 + 1e-9),
                note,
            )
        )
    return items


def _draw_link(axes, link: int, t, w_link, ours: list[float]) -> None:
    """Link ``link``'s tip deflection and its spectrum with the paper's peaks."""
    axes[link, 0].plot(t, 1e3 * w_link, lw=0.7)
    axes[link, 0].set(
        xlabel="t (s)",
        ylabel=f"w{link + 1}e (mm)",
        title=f"({'ace'[link]}) tip deflection of link {link + 1}",
    )
    freq, amp = amplitude_spectrum(w_link, SUBEDI_FIG14_DT_S, N_FFT)
    ax = axes[link, 1]
    ax.semilogy(freq, 1e3 * np.maximum(amp, 1e-12), lw=0.7, label="flexctrl (2048-point)")
    for j, paper in enumerate(SUBEDI_FIG14_PEAKS_HZ[link]):
        ax.axvline(paper, color="r", ls=":", lw=1, label="paper's peaks" if j == 0 else None)
    ax.plot(
        ours,
        [1e3 * amp[int(round(f / RESOLUTION_HZ))] for f in ours],
        "kv",
        label="flexctrl's peaks",
    )
    ax.set(
        xlim=(0, 60),
        ylim=(1e-4, None),
        xlabel="f (Hz)",
        ylabel=f"|W{link + 1}e(f)| (mm)",
        title=f"({'bdf'[link]}) spectrum of link {link + 1}",
    )
    ax.legend(fontsize=6)


def _fig14_text(runs: Runs) -> str:
    """The section's text: the method, every reading of the paper's spectrum tried."""
    found = readings(runs)
    rows = "\n".join(
        f"| {name} | "
        + " | ".join(", ".join(f"{f:.4f}" for f in link) for link in per_link)
        + f" | {matched(per_link)} of 6 |"
        for name, per_link in found
    )
    best = max(found, key=lambda case: matched(case[1]))
    return (
        "Damped free vibration under gravity (Fig 9's run, frozen modes), the first 2000 samples "
        "of w_ie at 1 ms "
        "(the tip deflection of link i in its own frame, Eq 2), mean removed, amplitude spectrum "
        "zero-padded to "
        "2048 points as the printed digits show the paper did. Verdict per peak: within one bin "
        "(0.488 Hz).\n\n"
        "Link 2's low peak, 0.883 Hz in the paper against 0.4883 Hz here. Every reading tried, "
        "with the two "
        "strongest peaks of each link (Hz) and how many of the six printed peaks it gives to "
        "their printed "
        "digits (0.01 Hz):\n\n| reading | link 1 | link 2 | link 3 | printed peaks reproduced |\n"
        "|---|---|---|---|---|\n" + rows + "\n\n"
        f"The best reading is '{best[0]}' ({matched(best[1])} of 6). A Hann window moves link "
        "2's low peak to "
        "0.9766 Hz (bin 2, nearer 0.883) but loses link 1's printed 1.465 Hz, so it is not the "
        "paper's reading. "
        "No reading can give 0.883 Hz, which lies between two bins of the grid all the other "
        "printed values sit "
        "on; the slow content of w_2e is the whole arm's swing under gravity (0.49 Hz in all "
        "three links), not a "
        "mode of link 2. Neither the window, the sampling, the transformed coordinate, the modes "
        "(frozen or "
        "scheduled) nor Eq 68's form explains it; the explanation left is a misprint of 0.4883."
    )
