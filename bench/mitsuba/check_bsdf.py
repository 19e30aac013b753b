#!/usr/bin/env python3
"""Self-tests of the Mitsuba plug-in in bench/mitsuba/lightcast_bsdf.py (lightcast's
metallic-roughness material), through Mitsuba's own BSDF interface (`scalar_rgb`):

0. tables: the E tables' quadrature error (each entry against one with 4× the points, and
   against a brute-force midpoint rule over the hemisphere where the lobe is wide enough for
   it) and their bilinear interpolation error (E_d at the cells' centres);
1. white furnace: the directional albedo, the mean of sample()'s weights, for base colour 1 at
   roughness 0.1, 0.5 and 1 and several view angles: a dielectric's is 1 up to the tables'
   error at that angle (computed and shown: the "expected" column), a metal's (F = 1) is the
   single-scattering GGX albedo A + B ≤ 1; and a sphere inside a `constant` emitter of radiance
   1 rendered by Mitsuba's `path` integrator, whose emitter sampling and MIS use eval() and
   pdf(): a dielectric white sphere must come out 1;
2. sampling consistency: the mean of sample()'s weights against eval()/pdf_uniform with
   stratified uniform hemisphere directions, for coloured bases at several metallic and
   roughness values (≥ 0.3: a narrower lobe is too peaked for uniform directions), and
   sample()'s pdf and weight against pdf() and eval() at the sampled direction;
3. independence: at metallic 1 and base colour 1 (F = 1), eval() and pdf() against Mitsuba's
   `roughconductor` (`distribution` ggx, `alpha` r², `material` none, i.e. η = 0, k = 1, whose
   Fresnel term is exactly 1) over a grid of directions; the table also gives the relative
   difference from the height-correlated Smith G, to show what a wrong G would look like.

Prints a table per part and exits 1 if any check fails. About a minute on 2 cores.

Usage:
    python3 bench/mitsuba/check_bsdf.py
"""

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import lightcast_bsdf as lb  # noqa: E402

import mitsuba as mi  # noqa: E402

mi.set_variant("scalar_rgb")
lb.register_bsdf(mi)

CTX = mi.BSDFContext()
FAILURES = []


def check(ok, what):
    if not ok:
        FAILURES.append(what)
    return "ok" if ok else "FAIL"


def lightcast(base, metallic, roughness):
    return mi.load_dict(
        {"type": "lightcast", "r": base[0], "g": base[1], "b": base[2],
         "metallic": metallic, "roughness": roughness}
    )


def interaction(wi):
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*wi)
    return si


def view(mu):
    return (math.sqrt(max(1 - mu * mu, 0.0)), 0.0, mu)


def sample_weights(bsdf, wi, n, rng):
    """sample()'s weights (n × 3) and, for each, its pdf and direction."""
    si = interaction(wi)
    u = rng.random((n, 3))
    weights, pdfs, dirs = np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3))
    for k in range(n):
        bs, w = bsdf.sample(CTX, si, float(u[k, 0]), mi.Point2f(float(u[k, 1]), float(u[k, 2])))
        weights[k] = (w[0], w[1], w[2])
        pdfs[k] = bs.pdf
        dirs[k] = (bs.wo[0], bs.wo[1], bs.wo[2])
    return weights, pdfs, dirs


def mean_sigma(x):
    return x.mean(0), x.std(0) / math.sqrt(len(x))


# ---------------------------------------------------------------------------------------------
# 0. Tables

def brute_force_albedo(mu, roughness, n=1000):
    """A + B by the midpoint rule over (θ_l, φ_l) (second order: within 10⁻⁵ at n = 1000 for
    r ≥ 0.3; narrower lobes need more), independent of the tables' sampling."""
    a2 = roughness**4
    theta = (np.arange(n) + 0.5) / n * np.pi / 2
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * np.pi  # f is even in φ: [0, π] twice
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    c, s = np.cos(theta), np.sin(theta)
    v = view(mu)
    hx, hy, hz = s * np.cos(phi) + v[0], s * np.sin(phi), c + v[2]
    cos_h = hz / np.sqrt(hx * hx + hy * hy + hz * hz)
    d = a2 / (np.pi * (cos_h * cos_h * (a2 - 1) + 1) ** 2)
    lam = lambda x: np.sqrt(a2 + (1 - a2) * x * x)  # noqa: E731
    f_cos = d / ((c + lam(c)) * (mu + lam(mu))) * c
    return float((f_cos * s).sum() * (np.pi / 2 / n) * (np.pi / (2 * n)) * 2)


def tables_part(table):
    print("## 0. E tables (%d×%d, %d points per entry)\n" % (table.size, table.size, lb.TABLE_SAMPLES))
    fine = lb.Tables(4 * lb.TABLE_SAMPLES)
    quad = max(np.abs(table.a - fine.a).max(), np.abs(table.b - fine.b).max())
    brute = 0.0
    for mu in (0.05, 0.3, 0.7, 1.0):
        for r in (0.3, 0.6, 1.0):
            a, b = lb.albedo_terms(np.array([mu]), r)
            brute = max(brute, abs(a[0] + b[0] - brute_force_albedo(mu, r)))
    # Interpolation: E_d looked up at every cell's centre against computed there.
    n = table.size - 1
    centres = (np.arange(n) + 0.5) / n
    err = np.zeros((n, n))
    for j, r in enumerate(np.maximum(centres, lb.MIN_ROUGHNESS)):
        a, b = lb.albedo_terms(centres, r)
        err[:, j] = [table.e_d(mu, r) - e for mu, e in zip(centres, lb.F0_DIELECTRIC * a + b)]
    print("| check | value | limit | |")
    print("|---|---|---|---|")
    print("| max |A, B − (4× points)| | %.1e | 5e-5 | %s |" % (quad, check(quad < 5e-5, "table quadrature")))
    print("| max |A + B − midpoint rule| (r ≥ 0.3) | %.1e | 2e-5 | %s |" % (brute, check(brute < 2e-5, "table vs midpoint rule")))
    for first, label in ((0, "all cells"), (1, "μ ≥ 1/%d" % n), (2, "μ ≥ 2/%d" % n)):
        e = np.abs(err[first:])
        i, j = np.unravel_index(e.argmax(), e.shape)
        print("| max |E_d(lookup) − E_d| at cell centres, %s | %.1e (μ %.3f, r %.3f) | (shown) | |"
              % (label, e[i, j], centres[first + i], max(centres[j], lb.MIN_ROUGHNESS)))
    e = np.abs(err[:, np.searchsorted(centres, 0.15):])
    print("| same, r ≥ 0.15 | %.1e | (shown) | |" % e.max())
    print()


# ---------------------------------------------------------------------------------------------
# 1. White furnace

def furnace_part(table, rng, n):
    print("## 1. White furnace (base colour 1; directional albedo = mean of %d sample() weights)\n" % n)
    print("| metallic | roughness | μ = n·v | albedo | 1σ | expected | |")
    print("|---|---|---|---|---|---|---|")
    for metallic in (0.0, 1.0):
        for r in (0.1, 0.5, 1.0):
            bsdf = lightcast((1, 1, 1), metallic, r)
            for mu in (0.02, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0):
                w, _, _ = sample_weights(bsdf, view(mu), n, rng)
                albedo, sigma = mean_sigma(w[:, 0])
                a, b = lb.albedo_terms(np.array([mu]), max(r, lb.MIN_ROUGHNESS), 16 * lb.TABLE_SAMPLES)
                e_true = a[0] + b[0] if metallic else lb.F0_DIELECTRIC * a[0] + b[0]
                if metallic:
                    expected = e_true  # F = 1: the GGX single-scattering albedo
                    ok = abs(albedo - expected) <= 4 * sigma + 1e-4 and albedo <= 1 + 4 * sigma
                else:
                    # diffuse (1 − E_d(table)) + specular E_d(true)
                    expected = 1 - table.e_d(mu, max(r, lb.MIN_ROUGHNESS)) + e_true
                    ok = abs(albedo - expected) <= 4 * sigma + 1e-4 and abs(expected - 1) < 5e-3
                print("| %g | %g | %g | %.5f | %.5f | %.5f | %s |" % (
                    metallic, r, mu, albedo, sigma, expected,
                    check(ok, "furnace m=%g r=%g mu=%g" % (metallic, r, mu))))
    print()


def furnace_render(r, spp):
    """Mean and 1σ of a white dielectric sphere's pixels inside a constant emitter of 1."""
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 64, "rr_depth": 1000},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "ball": {"type": "sphere", "radius": 1.0,
                 "bsdf": {"type": "lightcast", "r": 1.0, "g": 1.0, "b": 1.0,
                          "metallic": 0.0, "roughness": r}},
        "camera": {
            "type": "perspective", "fov": 30.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4.2], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    })
    img = np.array(mi.render(scene, spp=spp), dtype=np.float64)[..., 0]
    # Pixels whose whole area sees the sphere: centre within 0.9 of its projected radius.
    y, x = np.mgrid[0:24, 0:24] + 0.5
    t = math.tan(math.radians(15))
    px = (x / 24 * 2 - 1) * t
    py = (1 - y / 24 * 2) * t
    inside = np.hypot(px, py) < 0.9 / math.sqrt(4.2**2 - 1)
    return img[inside].mean(), img[inside].std() / math.sqrt(inside.sum()), int(inside.sum())


def furnace_render_part(spp):
    print("## 1b. White furnace render (dielectric white sphere in a constant emitter of 1, "
          "`path`, max_depth 64, %d spp)\n" % spp)
    print("| roughness | pixels | mean | 1σ | |")
    print("|---|---|---|---|---|")
    for r in (0.1, 0.5, 1.0):
        mean, sigma, n = furnace_render(r, spp)
        ok = abs(mean - 1) <= 4 * sigma + 2e-3
        print("| %g | %d | %.5f | %.5f | %s |" % (r, n, mean, sigma, check(ok, "furnace render r=%g" % r)))
    print()


# ---------------------------------------------------------------------------------------------
# 2. Sampling consistency

def uniform_estimate(bsdf, wi, side, reps, rng):
    """∫ f cos dω by stratified uniform hemisphere directions (side² strata, `reps` times)."""
    si = interaction(wi)
    est = np.zeros((reps, 3))
    j, i = np.mgrid[0:side, 0:side]
    for k in range(reps):
        c = (j.ravel() + rng.random(side * side)) / side
        phi = 2 * np.pi * (i.ravel() + rng.random(side * side)) / side
        s = np.sqrt(1 - c * c)
        total = np.zeros(3)
        for cz, sx, sy in zip(c, s * np.cos(phi), s * np.sin(phi)):
            f = bsdf.eval(CTX, si, mi.Vector3f(sx, sy, cz))
            total += (f[0], f[1], f[2])
        est[k] = total / (side * side) * 2 * np.pi
    return mean_sigma(est)


def consistency_part(rng, n, side, reps):
    print("## 2. Sampling consistency (base (0.9, 0.5, 0.2); sample() mean of %d weights vs "
          "eval() over %d×%d stratified uniform directions × %d)\n" % (n, side, side, reps))
    print("| metallic | roughness | μ | sample() R/G/B | uniform R/G/B | max |diff|/σ | max pdf, weight mismatch | |")
    print("|---|---|---|---|---|---|---|---|")
    base = (0.9, 0.5, 0.2)
    for metallic in (0.0, 0.5, 1.0):
        for r in (0.3, 0.6, 1.0):
            bsdf = lightcast(base, metallic, r)
            for mu in (0.2, 0.6, 0.95):
                wi = view(mu)
                w, pdfs, dirs = sample_weights(bsdf, wi, n, rng)
                ms, ss = mean_sigma(w)
                mu_u, su = uniform_estimate(bsdf, wi, side, reps, rng)
                z = np.abs(ms - mu_u) / np.sqrt(ss**2 + su**2)
                # sample()'s pdf and weight at its own direction against pdf() and eval().
                si = interaction(wi)
                mismatch = 0.0
                for k in range(0, n, 16):
                    if pdfs[k] <= 0:
                        continue
                    wo = mi.Vector3f(*dirs[k])
                    p = bsdf.pdf(CTX, si, wo)
                    f = bsdf.eval(CTX, si, wo)
                    mismatch = max(mismatch, abs(p / pdfs[k] - 1),
                                   *(abs(f[c] / p - w[k, c]) / max(w[k, c], 1e-12) for c in range(3)))
                ok = z.max() < 4 and mismatch < 1e-5
                print("| %g | %g | %g | %s | %s | %.1f | %.1e | %s |" % (
                    metallic, r, mu, " ".join("%.4f" % x for x in ms),
                    " ".join("%.4f" % x for x in mu_u), z.max(), mismatch,
                    check(ok, "consistency m=%g r=%g mu=%g" % (metallic, r, mu))))
    # Two-sided: the back side's values are the front side's mirrored.
    bsdf = lightcast(base, 0.5, 0.4)
    worst = 0.0
    for _ in range(200):
        wi, wo = rng.normal(size=3), rng.normal(size=3)
        wi, wo = wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)
        wi[2], wo[2] = abs(wi[2]), abs(wo[2])
        front = bsdf.eval_pdf(CTX, interaction(wi), mi.Vector3f(*wo))
        back = bsdf.eval_pdf(CTX, interaction(wi * [1, 1, -1]), mi.Vector3f(*(wo * [1, 1, -1])))
        worst = max(worst, abs(front[1] - back[1]), *(abs(front[0][c] - back[0][c]) for c in range(3)))
    print("\nTwo-sided: max |front − mirrored back| of eval() and pdf() over 200 direction pairs: "
          "%.1e %s\n" % (worst, check(worst == 0.0, "two-sided")))


# ---------------------------------------------------------------------------------------------
# 3. Against Mitsuba's roughconductor

def height_correlated(wi, wo, alpha):
    """D G2 / (4 cos_i) with the height-correlated G2 = 1/(1 + Λ(wi) + Λ(wo)): eval()'s value
    (F = 1, times cos_o) had the model used it."""
    a2 = alpha * alpha
    h = np.add(wi, wo)
    h = h / np.linalg.norm(h)
    d = a2 / (np.pi * (h[2] ** 2 * (a2 - 1) + 1) ** 2)
    lam = lambda c: (-1 + math.sqrt(1 + a2 * (1 - c * c) / (c * c))) / 2  # noqa: E731
    return d / (1 + lam(wi[2]) + lam(wo[2])) / (4 * wi[2])


def roughconductor_part(rng):
    print("## 3. Metallic 1, base colour 1 against Mitsuba's roughconductor (ggx, alpha = r², "
          "material none)\n")
    print("Directions: wo on a 5°×30° grid and 64 of our sample()'s per wi, wi at 0°, 20°, 45°, "
          "70°, 85°, 89°.\n")
    print("| roughness | directions | max rel. diff eval() | max rel. diff pdf() | "
          "max rel. diff of Mitsuba's eval() from height-correlated G | |")
    print("|---|---|---|---|---|---|")
    for r in (0.1, 0.3, 0.5, 0.8, 1.0):
        ours = lightcast((1, 1, 1), 1.0, r)
        alpha = max(r, lb.MIN_ROUGHNESS) ** 2
        theirs = mi.load_dict({"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
                               "material": "none"})
        d_eval = d_pdf = d_hc = 0.0
        count = 0
        for ti in (0, 20, 45, 70, 85, 89):
            wi = (math.sin(math.radians(ti)), 0.0, math.cos(math.radians(ti)))
            si = interaction(wi)
            grid = [
                (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))
                for t in np.radians(np.arange(0, 90, 5)) for p in np.radians(np.arange(0, 360, 30))
            ]
            _, pdfs, dirs = sample_weights(ours, wi, 64, rng)
            for wo in grid + [tuple(d) for d, p in zip(dirs, pdfs) if p > 0]:
                v = mi.Vector3f(*wo)
                fo, po = ours.eval_pdf(CTX, si, v)
                ft, pt = theirs.eval(CTX, si, v), theirs.pdf(CTX, si, v)
                count += 1
                d_eval = max(d_eval, *(abs(fo[c] / ft[c] - 1) for c in range(3)))
                d_pdf = max(d_pdf, abs(po / pt - 1))
                d_hc = max(d_hc, abs(ft[0] / height_correlated(wi, wo, alpha) - 1))
        ok = d_eval < 1e-4 and d_pdf < 1e-4
        print("| %g | %d | %.1e | %.1e | %.3f | %s |" % (
            r, count, d_eval, d_pdf, d_hc, check(ok, "roughconductor r=%g" % r)))
    print()


def main():
    t = time.time()
    rng = np.random.default_rng(2026)
    tables_part(lb.tables())
    furnace_part(lb.tables(), rng, n=1 << 14)
    furnace_render_part(spp=256)
    consistency_part(rng, n=1 << 14, side=32, reps=16)
    roughconductor_part(rng)
    print("%.0f s; %s" % (time.time() - t, "FAILED: " + "; ".join(FAILURES) if FAILURES else "all checks passed"))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
