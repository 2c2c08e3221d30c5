"""Dominant frequencies of a uniformly sampled signal (FFT amplitude peaks).

Used for the frequency-domain analysis of Subedi et al. (2021), Section 4.4: the
tip deflection of every link, sampled at the integration step, over the first
2 s of a free-vibration run.
"""

from __future__ import annotations

import numpy as np


def amplitude_spectrum(
    signal: np.ndarray, dt: float, n_fft: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum of ``signal`` (mean removed).

    Parameters
    ----------
    signal : numpy.ndarray
        Uniform samples.
    dt : float
        Sample interval (s).
    n_fft : int, optional
        Transform length: the signal is zero-padded to it (e.g. ``2**ceil(log2 n)``, as
        MATLAB's ``nextpow2`` idiom does); default ``len(signal)``.

    Returns
    -------
    freq : numpy.ndarray
        Frequencies (Hz), bin spacing ``1 / (n_fft dt)``.
    amplitude : numpy.ndarray
        ``|FFT| * 2 / n`` with n the signal's length (a sine of amplitude A shows as about A
        on its bin).
    """
    signal = np.asarray(signal, dtype=float)
    n = signal.size
    n_fft = n if n_fft is None else int(n_fft)
    if n_fft < n:
        raise ValueError(
            f"n_fft {n_fft} is shorter than the signal ({n} samples); allowed: n_fft >= {n}"
        )
    amplitude = np.abs(np.fft.rfft(signal - signal.mean(), n_fft)) * 2.0 / max(n, 1)
    return np.fft.rfftfreq(n_fft, dt), amplitude


def dominant_frequencies(
    signal: np.ndarray, dt: float, count: int = 2, *, floor: float = 1e-3, n_fft: int | None = None
) -> list[float]:
    """The ``count`` strongest spectral peaks of ``signal`` (Hz), strongest first.

    A peak is a bin larger than both neighbours (the zero-frequency bin is left
    out); peaks weaker than ``floor`` times the strongest are dropped, so a
    signal that is identically zero has no dominant frequency.

    Parameters
    ----------
    signal : numpy.ndarray
        Samples, shape (N,).
    dt : float
        Sample time (s).
    count : int
        Number of peaks returned at most.
    floor : float
        Share of the strongest peak below which a peak is dropped.
    n_fft : int, optional
        Zero-padded transform length, as in :func:`amplitude_spectrum`.

    Returns
    -------
    list of float
        Peak frequencies (Hz), strongest first.

    Examples
    --------
    >>> t = np.arange(2000) * 1e-3
    >>> dominant_frequencies(np.sin(2 * np.pi * 5 * t) + 0.1 * np.sin(2 * np.pi * 40 * t), 1e-3)
    [5.0, 40.0]
    """
    freq, amp = amplitude_spectrum(signal, dt, n_fft)
    if amp.size < 3 or not np.any(amp[1:] > 0):
        return []
    inner = np.arange(1, amp.size - 1)
    peaks = inner[(amp[inner] > amp[inner - 1]) & (amp[inner] >= amp[inner + 1])]
    if amp[-1] > amp[-2]:
        peaks = np.append(peaks, amp.size - 1)
    if peaks.size == 0:
        return []
    peaks = peaks[np.argsort(amp[peaks])[::-1]]
    strongest = amp[peaks[0]]
    strong = [p for p in peaks if amp[p] >= floor * strongest]
    return [float(freq[p]) for p in strong[:count]]
