"""The report's figures of the design studies (Fig. 20-25): ball count and the journal-bushing clearance joint."""
from __future__ import annotations


import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mechanism.output.plots import crank_pi, plot_trajectory  # noqa: E402
from mechanism.studies.reproduce.analysis import (crank_period, half_clearance_of, on_times, rms, rms_deviation, vibration_frequency, window)  # noqa: E402
from mechanism.studies.reproduce.drawing import (decreasing, fmt, save_figure, pi_axis, verdict_word)  # noqa: E402
from mechanism.studies.reproduce.verdicts import ALIKE, STEADY  # noqa: E402
from mechanism.studies.reproduce.paper import (CLAIMS, VIBRATION_MIN_HARMONIC)  # noqa: E402


class DesignFigures:
    """Fig. 20-25 of the paper: 8/15/20 balls and the clearance joint (a ``Report`` mixin)."""

    def fig20(self):
        names = list(self.balls.values())
        if not self.has(*names):
            return
        fig, ax = plt.subplots(figsize=(6.5, 6))
        for n, name in self.balls.items():
            plot_trajectory(ax, self.runs[name], f"{n} balls", clearance=(n == 20))
        ax.legend(fontsize=8)
        ax.set_title("Fig. 20: trajectories, 1200 rpm, 8/15/20 balls")
        fname = save_figure(fig, self.fig_dir / "fig20_ball_count_trajectories.png")
        emax = [self.table[n]["max_e"] for n in names]
        self.w("### Fig. 20 — trajectories for 8, 15 and 20 balls at 1200 rpm")
        self.w()
        self.figure(fname, "Journal centre relative to the housing [µm]. 15 and 20 balls of 8.7 mm do not fit on the "
                           "37.9 mm pitch circle (13 at most): those runs set allow_ball_overlap — a hypothetical "
                           "bearing, as in the paper.")
        self.w(f"Paper: {CLAIMS['fig20']}.")
        self.w()
        self.w(f"Ours: max |e| = {', '.join(f'{e * 1e6:.2f}' for e in emax)} µm for {', '.join(map(str, self.balls))} "
               f"balls: {verdict_word(decreasing(emax))}.")
        self.w()
        self.verdict("Fig. 20", STEADY, [decreasing(emax)], "max |e| strictly decreases from 8 to 15 to 20 balls",
                     "the trend, for a hypothetical bearing: 15 and 20 balls do not fit on the pitch circle "
                     "(allow_ball_overlap); the paper runs them without saying so")
        self.w()

    def fig21(self):
        names = list(self.balls.values())
        if not self.has(*names, self.i1200):
            return
        i = self.runs[self.i1200]
        fig, axes = plt.subplots(2, 2, figsize=(11, 7))
        for ax, (col, label) in zip(axes.flat, (("slider_a", "slider acceleration [m/s²]"),
                                               ("crank_moment", "crank moment [N·m]"),
                                               ("F_x", "joint force F_x [N]"), ("F_y", "joint force F_y [N]"))):
            ax.plot(crank_pi(i), i[col], "k", lw=1.2, label="ideal joint")
            for n, name in self.balls.items():
                r = self.runs[name]
                ax.plot(crank_pi(r), r[col], lw=0.7, label=f"{n} balls")
            ax.set_ylabel(label)
            ax.legend(fontsize=7)
            pi_axis(ax)
        fig.suptitle("Fig. 21: responses at 1200 rpm for 8/15/20 balls")
        fname = save_figure(fig, self.fig_dir / "fig21_ball_count_responses.png")
        dev = {col: [rms_deviation(self.runs[n], i, col) for n in names] for col in ("slider_a", "crank_moment", "F_x", "F_y")}
        self.w("### Fig. 21 — slider acceleration, crank moment and joint forces for 8, 15, 20 balls")
        self.w()
        self.figure(fname, "(a) slider acceleration, (b) crank moment, (c) F_x, (d) F_y at 1200 rpm.")
        self.w(f"Paper: {CLAIMS['fig21']}.")
        self.w()
        units = {"slider_a": "m/s²", "crank_moment": "N·m", "F_x": "N", "F_y": "N"}
        self.w("Ours: RMS deviation from the ideal joint for " + ", ".join(map(str, self.balls)) + " balls: " +
               "; ".join(f"{col}: {', '.join(fmt(x) for x in v)} {units[col]}" for col, v in dev.items()) +
               f": {verdict_word(all(decreasing(v) for v in dev.values()))} (all decrease).")
        self.w()
        self.verdict("Fig. 21", STEADY, [decreasing(v) for v in dev.values()],
                     "the RMS deviation from the ideal joint strictly decreases with the ball count, for each of "
                     "slider acceleration, crank moment, F_x and F_y",
                     "" if all(decreasing(v) for v in dev.values()) else
                     "ours: more balls make the bearing stiffer but not smoother at 1200 rpm — the vibration is "
                     "excited by balls entering the load zone, which more balls do more often")

    def fig22(self):
        names = list(self.balls.values())
        if not self.has(*names):
            return
        fig, ax = plt.subplots(figsize=(9, 4))
        peaks = []
        for n, name in self.balls.items():
            r = self.runs[name]
            ax.plot(crank_pi(r), r["ball_load_1"], lw=0.8, label=f"{n} balls")
            peaks.append(float(np.max(r["ball_load_1"])))
        ax.set_ylabel("load on ball 1 [N]")
        ax.legend(fontsize=8)
        pi_axis(ax)
        ax.set_title("Fig. 22: load on ball 1, 1200 rpm")
        fname = save_figure(fig, self.fig_dir / "fig22_ball1_load.png")
        maxload = [self.table[n]["max_ball_load"] for n in names]
        self.w("### Fig. 22 — load on ball 1 for 8, 15, 20 balls")
        self.w()
        self.figure(fname, "Load on ball 1 [N] at 1200 rpm.")
        self.w(f"Paper: {CLAIMS['fig22']}.")
        self.w()
        self.w(f"Ours: largest load on any ball over the second revolution = "
               f"{', '.join(f'{x:.1f}' for x in maxload)} N for {', '.join(map(str, self.balls))} balls: "
               f"{verdict_word(decreasing(maxload))}. Ball 1 alone peaks at {', '.join(f'{x:.1f}' for x in peaks)} N over the "
               "whole run (mostly at the start, where it sits in the load zone); later it carries load only when the "
               "cage brings it there.")
        self.w()
        self.verdict("Fig. 22", STEADY, [decreasing(maxload)], "the largest load on any ball over the second "
                     "revolution strictly decreases with the ball count (ball 1 alone depends on where the cage "
                     "puts it, so the verdict uses every ball)")

    def fig23_24(self):
        if not self.has(self.b1200, self.clear):
            return
        b, c = self.runs[self.b1200], self.runs[self.clear]
        fig, axes = plt.subplots(1, 2, figsize=(11, 5.5))
        plot_trajectory(axes[0], b, "ball bearing")
        axes[0].set_title("(a) deep-groove ball bearing, 8 balls")
        axes[1].plot(c["e_x"] * 1e6, c["e_y"] * 1e6, lw=0.7, color="C1", label="journal in bushing")
        phi = np.linspace(0, 2 * np.pi, 200)
        hc = half_clearance_of(c) * 1e6
        axes[1].plot(hc * np.cos(phi), hc * np.sin(phi), "k--", lw=0.6, label="clearance c")
        axes[1].set_aspect("equal", adjustable="datalim")
        axes[1].grid(alpha=0.3)
        axes[1].set_xlabel("e_x [µm]")
        axes[1].set_ylabel("e_y [µm]")
        axes[1].set_title("(b) clearance joint (Lankarani–Nikravesh)")
        for ax in axes:
            ax.legend(fontsize=7)
        fig.suptitle("Fig. 23–24: journal-centre trajectories at 1200 rpm")
        fname = save_figure(fig, self.fig_dir / "fig23_24_clearance_trajectories.png")
        eb, ec = self.table[self.b1200]["max_e"], self.table[self.clear]["max_e"]
        mb = window(b)
        ang_b = np.unwrap(np.arctan2(b["e_y"], b["e_x"]))
        ang_c = np.interp(b["time"], c["time"], np.unwrap(np.arctan2(c["e_y"], c["e_x"])))
        dang = np.angle(np.exp(1j * (ang_b - ang_c)))[mb]
        self.w("### Fig. 23–24 — ball bearing vs the journal-bushing clearance joint: trajectories at 1200 rpm")
        self.w()
        self.figure(fname, "Fig. 23 of the paper sketches the two models; Fig. 24 is the clearance joint's trajectory. "
                           "Same free play per side (10 µm).")
        self.w(f"Paper: {CLAIMS['fig24']}.")
        self.w()
        self.w(f"Ours: max |e| = {eb * 1e6:.2f} µm (bearing) and {ec * 1e6:.2f} µm (clearance joint), ratio "
               f"{eb / ec:.2f}; the directions of e differ by {np.degrees(rms(dang)):.1f}° RMS over the second "
               f"revolution. Alike in size (ratio within {ALIKE[0]:g} … {ALIKE[1]:g}): "
               f"{verdict_word(ALIKE[0] <= eb / ec <= ALIKE[1])}; alike in shape (directions within 30° RMS): "
               f"{verdict_word(np.degrees(rms(dang)) < 30)}.")
        self.w()
        self.verdict("Fig. 23–24", STEADY, [ALIKE[0] <= eb / ec <= ALIKE[1], bool(np.degrees(rms(dang)) < 30)],
                     f"max |e| ratio within {ALIKE[0]:g} … {ALIKE[1]:g} (size) and directions of e within 30° RMS (shape)",
                     "" if ALIKE[0] <= eb / ec <= ALIKE[1] else
                     "ours: with the same free play, the journal in a conformal bushing deflects less than a ball "
                     "bearing whose load passes through two Hertz point contacts per ball in series; the paper's "
                     "\"quite similar\" is a qualitative reading of two plots")

    def fig25(self):
        if not self.has(self.b1200, self.clear, self.i1200):
            return
        b, c, i = self.runs[self.b1200], self.runs[self.clear], self.runs[self.i1200]
        fig, axes = plt.subplots(2, 2, figsize=(11, 7))
        for ax, (col, label) in zip(axes.flat, (("slider_a", "slider acceleration [m/s²]"),
                                               ("crank_moment", "crank moment [N·m]"),
                                               ("F_x", "joint force F_x [N]"), ("F_y", "joint force F_y [N]"))):
            ax.plot(crank_pi(i), i[col], "k", lw=1.2, label="ideal joint")
            ax.plot(crank_pi(b), b[col], lw=0.7, label="ball bearing")
            ax.plot(crank_pi(c), c[col], lw=0.7, label="clearance joint")
            ax.set_ylabel(label)
            ax.legend(fontsize=7)
            pi_axis(ax)
        fig.suptitle("Fig. 25: responses at 1200 rpm, ball bearing vs clearance joint")
        fname = save_figure(fig, self.fig_dir / "fig25_clearance_responses.png")
        # spectra of the deviation from the ideal joint
        fig, ax = plt.subplots(figsize=(9, 4))
        f_lo = VIBRATION_MIN_HARMONIC / crank_period(b)
        freqs = {}
        for r, label in ((b, "ball bearing"), (c, "clearance joint")):
            x = r["slider_a"] - on_times(i, r, "slider_a")
            dt = float(np.median(np.diff(r["time"])))
            amp = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x)))) * 2 / len(x)
            f = np.fft.rfftfreq(len(x), dt)
            ax.semilogy(f, amp + 1e-12, lw=0.7, label=label)
            freqs[label] = vibration_frequency(r, i)
        ax.axvline(f_lo, color="k", lw=0.6, ls=":", label=f"{VIBRATION_MIN_HARMONIC}× crank frequency")
        ax.set_xlim(0, min(20000, 0.5 / dt))
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("|FFT| of slider acc. − ideal [m/s²]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title("Spectrum of the slider-acceleration deviation, 1200 rpm")
        fname2 = save_figure(fig, self.fig_dir / "fig25_vibration_spectrum.png")
        rel = rms_deviation(c, b, "slider_a") / rms(b["slider_a"][window(b)])
        fb, fc = freqs["ball bearing"], freqs["clearance joint"]
        self.w("### Fig. 25 — responses at 1200 rpm, ball bearing vs clearance joint")
        self.w()
        self.figure(fname, "(a) slider acceleration, (b) crank moment, (c) F_x, (d) F_y.")
        self.figure(fname2, "Amplitude spectrum of the slider acceleration minus the ideal joint's (whole run).")
        self.w(f"Paper: {CLAIMS['fig25']}.")
        self.w()
        self.w(f"Ours: the two joints' slider accelerations differ by {rel * 100:.2f} % RMS (relative to the bearing's "
               f"RMS): roughly the same. Dominant vibration frequency of the deviation from the ideal joint (above "
               f"{f_lo:.0f} Hz): {fb:.0f} Hz (ball bearing) and {fc:.0f} Hz (clearance joint), ratio {fc / fb:.2f}: "
               f"{verdict_word(rel < 0.1 and abs(fc / fb - 1) > 0.2)} that they differ (the clearance model's sphere-to-sphere "
               "stiffness is not the ball bearing's), though by more than the paper's \"slightly\".")
        self.w()
        self.verdict("Fig. 25", "whole run (spectrum), steady (RMS)", [rel < 0.1, abs(fc / fb - 1) > 0.2],
                     "the slider accelerations differ by < 10 % RMS (\"roughly the same\") and the dominant vibration "
                     "frequencies by > 20 % (\"slightly different\")",
                     "" if rel < 0.1 else "ours, as measured: the two contact models vibrate at different frequencies, "
                     "so the pointwise difference is large even where the envelopes look alike")

    # ------------------------------------------------------------------------------------------
