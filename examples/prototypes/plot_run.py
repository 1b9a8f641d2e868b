"""One run's story in five panels (error and cloud std, heading error and std, ESS, reinit): a PNG.

    ../../.venv/bin/python plot_run.py OUT WORLD RUN VARIANT[,VARIANT...] PNG
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd


def main(out, world, run, variants, png):
    fig, ax = plt.subplots(4, 1, figsize=(11, 10), sharex=True)
    for v in variants.split(","):
        r = pd.read_parquet(f"{out}/{world}/{v}/run-{int(run):05d}.parquet")
        t = r["t"] - r["t"].iloc[0]
        l0, = ax[0].semilogy(t, r["horizontal_error_m"], label=f"{v} error")
        ax[0].semilogy(t, np.sqrt(r["var_e"] + r["var_n"]), ":", color=l0.get_color(), label=f"{v} std")
        if "pcrb_horizontal_m" in r:
            ax[0].semilogy(t, r["pcrb_horizontal_m"], "--", color=l0.get_color(), lw=0.6)
        ax[1].plot(t, r["heading_error_deg"], color=l0.get_color())
        if "var_heading" in r:
            ax[1].plot(t, 3 * np.sqrt(r["var_heading"]), ":", color=l0.get_color())
            ax[1].plot(t, -3 * np.sqrt(r["var_heading"]), ":", color=l0.get_color())
        ax[2].semilogy(t, r["ess"], color=l0.get_color())
        if "reinit" in r:
            for tt in t[r["reinit"] > 0]:
                ax[3].axvline(tt, color=l0.get_color(), lw=0.8)
        if "best_chi2" in r:
            ax[3].semilogy(t, r["best_chi2"], color=l0.get_color())
        if "fix_accepted" in r:
            ax[3].plot(t[r["fix_accepted"] > 0], np.full((r["fix_accepted"] > 0).sum(), 1.0), "|",
                       color=l0.get_color())
            ax[3].plot(t[r["fix_rejected"] > 0], np.full((r["fix_rejected"] > 0).sum(), 2.0), "x",
                       color=l0.get_color())
    ax[0].legend(fontsize=7)
    ax[0].set_ylabel("horizontal error / std (m)")
    ax[1].set_ylabel("heading error, +-3 std (deg)")
    ax[2].set_ylabel("ESS")
    ax[3].set_ylabel("reinit / best chi2 / fixes")
    ax[3].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(png, dpi=80)


if __name__ == "__main__":
    main(*sys.argv[1:])
