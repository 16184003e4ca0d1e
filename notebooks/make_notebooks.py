"""Write the example notebooks (stored without outputs; the test suite executes them).

Run from the repository root: ``.venv/bin/python notebooks/make_notebooks.py``.
"""

from __future__ import annotations

import pathlib

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = pathlib.Path(__file__).resolve().parent

SETUP = """\
import jax
jax.config.update("jax_enable_x64", True)   # the library never does this itself
import numpy as np
import matplotlib.pyplot as plt
import jmse_jax as jj"""

NOTEBOOKS = {
    "quickstart": [
        ("md", """\
# jmse_jax quickstart

Seidel coefficients (waves) → OTF → error spectral density `S_e` → JMSE and its gradient.
Frequencies are in units of the optical cutoff `1/(λN)`; `u` is the sensor Nyquist frequency
in the same units."""),
        ("code", SETUP),
        ("md", "The paper's Fig. 1 point (Berkner & Shroff): field 0.95, u = 0.2."),
        ("code", """\
ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
field, u = 0.95, 0.2
signal, noise = jj.MarkovSignal(variance=1.0, correlation_length=5.0), jj.WhiteNoise(1e-3)
ab"""),
        ("md", "## Wavefront (OPD) over the pupil"),
        ("code", """\
c = np.linspace(-1, 1, 64)
x, y = np.meshgrid(c, c)
opd = np.where(x**2 + y**2 <= 1, np.asarray(jj.wavefront(ab, x, y, field)), np.nan)
plt.imshow(opd, origin="lower", extent=(-1, 1, -1, 1), cmap="RdBu_r")
plt.colorbar(label="OPD [waves]"); plt.title("wavefront"); plt.show()"""),
        ("md", "## OTF along the axes and against the diffraction limit"),
        ("code", """\
nu = np.linspace(0.0, 0.6, 61)
h_x = np.asarray(jj.otf(ab, nu, 0 * nu, field))
h_y = np.asarray(jj.otf(ab, 0 * nu, nu, field))
plt.plot(nu, np.abs(h_x), label="|H(ν, 0)|")
plt.plot(nu, np.abs(h_y), label="|H(0, ν)|")
plt.plot(nu, np.asarray(jj.diffraction_limited_otf(nu)), "k--", label="diffraction limit")
plt.axvline(u, color="0.5", linestyle=":", label="Nyquist u")
plt.xlabel("ν [cutoff units]"); plt.ylabel("MTF"); plt.legend(); plt.show()"""),
        ("md", "## Error spectral density over the sensor band"),
        ("code", """\
f = np.linspace(-u, u, 41)
fx, fy = np.meshgrid(f, f)
h = jj.otf(ab.without_tilt(), fx, fy, field)
s_e = np.asarray(jj.error_spectral_density(h, signal(fx, fy), noise(fx, fy)))
plt.imshow(np.log10(s_e), origin="lower", extent=(-u, u, -u, u), cmap="gray")
plt.colorbar(label="log10 S_e"); plt.xlabel("ν_x"); plt.ylabel("ν_y"); plt.show()"""),
        ("md", "## JMSE and its gradient (fast preset here; the default is more accurate)"),
        ("code", """\
value, grad = jax.value_and_grad(jj.jmse)(ab, field, u, signal, noise, preset="fast")
print(f"JMSE = {value:.8e}   (converged value 2.6539432e-3)")
for name in ("w020", "w040", "w131", "w222", "w220"):
    print(f"dJMSE/d{name} = {getattr(grad, name):+.4e} per wave")
assert abs(value / 2.6539432e-3 - 1) < 1e-4"""),
        ("code", """\
baseline = jj.baseline_jmse(ab, field, u, signal, noise, B=64)
print(f"paper's FFT baseline B=64: {baseline:.6e} ({baseline / value - 1:+.1%})")"""),
    ],
    "paper_reproduced": [
        ("md", """\
# Berkner & Shroff reproduced (small)

Fig. 1 (OPD and `log10 S_e` of the paper's operating point), Fig. 4 right (JMSE versus the
number of frequency nodes for the quadrature rules) and Fig. 4 left (error of the wavefront
rebuilt from polar samples), at small sizes. `jmse-jax reproduce`
writes the same at larger sizes; `benchmarks/paper_figures.py` the full experiments."""),
        ("code", SETUP + "\nfrom jmse_jax import _reproduce as rp"),
        ("md", "## Fig. 1 point: baseline vs the quadrature JMSE"),
        ("code", """\
ab = jj.Seidel(**rp.FIG1)
signal, noise = rp.fig1_spectra()
ours = float(jj.jmse(ab, rp.FIG1_FIELD, rp.FIG1_U, signal, noise, preset="fast"))
base = float(jj.baseline_jmse(ab, rp.FIG1_FIELD, rp.FIG1_U, signal, noise, B=64))
print(f"jmse (fast) {ours:.7e}, baseline B=64 {base:.7e} ({base / ours - 1:+.1%})")"""),
        ("md", "## Fig. 1 maps"),
        ("code", """\
import os, tempfile
from IPython.display import Image
out = tempfile.mkdtemp()
info = rp.fig1_maps(os.path.join(out, "fig1.png"), n_pupil=48, n_freq=41,
                   preset="fast")
print({k: info[k] for k in ("opd_min", "opd_max", "opd_rms")})
Image(os.path.join(out, "fig1.png"))"""),
        ("md", """\
## Fig. 4 right: JMSE versus p

At defocus −2.75 (the Fig. 1 point) and −6 waves. The rectangle rule (the baseline's) and
equispaced rules converge slowly; Gauss rules fast, the polar panels fastest."""),
        ("code", """\
data = rp.fig4_right(ps=(4, 8, 16), reference_preset="fast")
rp.plot_fig4_right(data, os.path.join(out, "fig4_right.png"))
for defocus, block in data["defocus"].items():
    print(defocus, {r: f"{block['rules'][r]['relative_error']['16']:.1e}" for r in data["rules"]})
Image(os.path.join(out, "fig4_right.png"))"""),
        ("md", """\
## Fig. 4 left: the wavefront rebuilt from L rings x K arms

RMS error (waves) over random Seidel designs. The paper interpolated the polar samples
(cubic); projecting them onto Zernike polynomials by quadrature is exact from L = 3 rings."""),
        ("code", """\
left = rp.opd_error(6, (2, 3, 4, 6), (4, 6, 8, 16, 40))
rp.plot_fig4_left(left, os.path.join(out, "fig4_left.png"))
print("cubic:", left["cubic"]["fewest_samples"], " Zernike:", left["zernike"]["fewest_samples"])
Image(os.path.join(out, "fig4_left.png"))"""),
    ],
    "lens_optimisation": [
        ("md", """\
# Optimising the paper's singlet for the JMSE

The F/4.6, f = 9 mm, 10° N-BK7 singlet (lengths in mm, curvatures in 1/mm). Variables: front
curvature, stop position and focus; the back curvature is solved for F/4.6. Objective: the JMSE
averaged over fields 0, 0.7, 1 (preset "fast" to keep this quick)."""),
        ("code", SETUP + "\nfrom jmse_jax import lens as jl"),
        ("code", """\
start = jl.paper_singlet(1.0, 0.05, image_shift=0.0)
variables = ("curvatures[0]", "stop_position", "image_shift")
result = jj.optimise(start, variables, f_number=4.6, jmse_options={"preset": "fast"})
print(result.summary())
assert result.jmse < result.start_jmse"""),
        ("md", "Seidel coefficients (waves) of the start and of the optimum at full field:"),
        ("code", """\
for name, lens in (("start", start), ("optimum", result.lens)):
    print(name, jl.seidel_waves(lens))"""),
        ("code", """\
fields = np.asarray(result.fields)
plt.plot(fields, result.jmse_per_field, "o-", label="JMSE-optimal")
plt.xlabel("field"); plt.ylabel("JMSE"); plt.legend(); plt.show()"""),
        ("md", """\
Whether the optimum's JMSE at each field is held to the preset's accuracy:
`result.beyond_checked` is True at a field whose design lies beyond what the preset was
checked at (the summary flags it). `lens_beyond_checked` asks the same of any lens, here the
start focused 5 mm off (about 50 waves of defocus):"""),
        ("code", """\
far = jl.paper_singlet(1.0, 0.05, image_shift=5.0)
result.beyond_checked, jj.lens_beyond_checked(far, jmse_options={"preset": "fast"})"""),
    ],
    "sweeps": [
        ("md", """\
# Sweeping the JMSE over an aberration hypercube

`hypercube` builds every combination of the axes; `sweep_jmse` evaluates them one design at
a time on a CPU, from one host thread per core (`workers`), and with `vmap` in chunks of
`batch_size` on a GPU; with several devices the designs are sharded over them. Coefficients
in waves."""),
        ("code", SETUP),
        ("code", """\
cube = jj.hypercube(w020=np.linspace(-3, 3, 5), w222=np.linspace(-1.5, 1.5, 3))
ab = jj.Seidel(w020=cube["w020"], w222=cube["w222"], w040=0.5)
result = jj.sweep_jmse(ab, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                       preset="fast", progress=False)
result, result.status_counts(), result.metadata["workers"]"""),
        ("md", """\
A design beyond what the preset was checked at (too strong, too steep, terms that cancel, a
noise too low) gets a warning before the sweep, and is marked in `result.beyond_checked`:
`result.in_checked_range` selects the values held to the preset's accuracy."""),
        ("code", """\
int(result.ok.sum()), int(result.in_checked_range.sum())"""),
        ("code", """\
grid = np.asarray(result.value).reshape(5, 3)
plt.imshow(np.log10(grid).T, origin="lower", aspect="auto", extent=(-3, 3, -1.5, 1.5))
plt.colorbar(label="log10 JMSE"); plt.xlabel("w020 [waves]"); plt.ylabel("w222 [waves]")
plt.show()"""),
        ("md", "Results save to `.npz` + a JSON header and load back:"),
        ("code", """\
import os, tempfile
path = result.save(os.path.join(tempfile.mkdtemp(), "sweep"))
again = jj.SweepResult.load(path)
assert np.allclose(again.value, result.value)
path"""),
    ],
}


def build(name, cells) -> nbformat.NotebookNode:
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3",
                                 "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    nb.cells = [new_markdown_cell(src) if kind == "md" else new_code_cell(src)
                for kind, src in cells]
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"{name[:12]}-{i:02d}"  # stable ids: regenerating changes nothing
    return nb


def main():
    for name, cells in NOTEBOOKS.items():
        nb = build(name, cells)
        nbformat.validate(nb)
        nbformat.write(nb, HERE / f"{name}.ipynb")
        print(f"wrote {HERE / f'{name}.ipynb'}")


if __name__ == "__main__":
    main()
