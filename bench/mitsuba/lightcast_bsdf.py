#!/usr/bin/env python3
"""lightcast's material model (glTF 2.0 metallic-roughness) for Mitsuba 3, written from its
formulas, independently of the renderer's Rust/WGSL code.

Per surface: linear base colour c, metallic m ∈ [0, 1], roughness r clamped to ≥ 0.045,
α = r², a2 = α². In the shading frame (normal n = +z), with v the view direction, l the light
direction and h = normalize(l + v):

    D(h)  = a2 / (π ((n·h)² (a2 − 1) + 1)²)                              (GGX)
    G1(x) = 2 (n·x) / ((n·x) + √(a2 + (1 − a2)(n·x)²)),  G = G1(l) G1(v)   (separable Smith)
    F     = F0 + (1 − F0)(1 − v·h)⁵,  F0 = mix(0.04, c, m)                 (Schlick)
    f_s   = F D G / (4 (n·l)(n·v))
    f_d   = (1 − m) c/π · (1 − E_d(n·l)) (1 − E_d(n·v)) / (1 − Ē_d)
    f     = f_d + f_s, two-sided (the side facing the incoming ray is the front).

E tables: A(μ, r) and B(μ, r) are f_s's directional albedo at view cosine μ split in Schlick's
two terms, A with weight 1 − (1 − v·h)⁵ and B with (1 − v·h)⁵, so the specular albedo is
F0·A + B. E_d = 0.04·A + B is a dielectric's, Ē_d(r) = 2 ∫₀¹ E_d(μ, r) μ dμ its cosine-weighted
mean. The tables hold 32 × 32 entries at μ_i = max((i/31)², 10⁻³), r_j = j/31 (each entry at
max(r_j, 0.045)), looked up bilinearly in (√μ, r) at the clamped r (as the renderer's table:
a smooth lobe's albedo changes fastest at grazing angles); each entry is a Hammersley quadrature
with visible-normal (VNDF) sampling, whose weight G1(l)·(Schlick term) lies in [0, 1]
(half-vector D·cos sampling is 100× less accurate at grazing μ for the same count). Ē_d is the
exact integral of the interpolant, so the diffuse lobe's albedo is exactly
(1 − m) c (1 − E_d(n·v)) and a white dielectric's total albedo is 1 up to the tables' error.

Sampling: a cosine-weighted hemisphere or GGX visible normals (Heitz 2018), the diffuse lobe
with probability lum((1 − m) c)(1 − E_d(n·v)) / (that + lum(F0)·A(n·v) + B(n·v)); pdf() is the
mixture's.

Usage:
    import lightcast_bsdf; lightcast_bsdf.register_bsdf(mi)   # after mi.set_variant("scalar_rgb")
    {"type": "lightcast", "r": 0.8, "g": 0.55, "b": 0.3, "metallic": 0.0, "roughness": 1.0}

    python3 bench/mitsuba/lightcast_bsdf.py [--samples N] > tables.json
        # A, B (indexed [mu][r]) and Ē_d at the r nodes, to compare with another table
"""

import argparse
import json
import math
import sys

import numpy as np

MIN_ROUGHNESS = 0.045
F0_DIELECTRIC = 0.04
TABLE_SIZE = 32
MIN_TABLE_MU = 1e-3
TABLE_SAMPLES = 65536


def luminance(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


# ---------------------------------------------------------------------------------------------
# The E tables (numpy)

def hammersley(n):
    """n points of the Hammersley set in [0, 1)²: (i + ½)/n and the base-2 radical inverse."""
    i = np.arange(n, dtype=np.uint64)
    bits = np.zeros(n, np.uint64)
    for k in range(32):
        bits |= ((i >> np.uint64(k)) & np.uint64(1)) << np.uint64(31 - k)
    return (np.arange(n) + 0.5) / n, bits.astype(np.float64) / 2.0**32


def smith_g1(cos, a2):
    return 2 * cos / (cos + np.sqrt(a2 + (1 - a2) * cos * cos))


def table_nodes(size=TABLE_SIZE):
    """(μ at each row, roughness at each column) as the entries are computed."""
    x = np.arange(size) / (size - 1)
    return np.maximum(x * x, MIN_TABLE_MU), np.maximum(x, MIN_ROUGHNESS)


def albedo_terms(mu, roughness, samples=TABLE_SAMPLES):
    """A and B at view cosines `mu` (1-D array) for one roughness (already clamped)."""
    alpha = roughness * roughness
    a2 = alpha * alpha
    u1, u2 = hammersley(samples)
    mu = np.asarray(mu, np.float64)[:, None]
    v = (np.sqrt(1 - mu * mu), np.zeros_like(mu), mu)
    # Heitz 2018: sample the visible hemisphere of the view direction stretched by α. The
    # view direction lies in the xz-plane, so its stretched frame's first tangent is +y.
    sx, sz = alpha * v[0], v[2]
    norm = np.sqrt(sx * sx + sz * sz)
    sx, sz = sx / norm, sz / norm
    t2x, t2z = -sz, sx  # T2 = stretched view × T1, T1 = (0, 1, 0)
    radius = np.sqrt(u1)
    phi = 2 * np.pi * u2
    p1 = radius * np.cos(phi)
    p2 = radius * np.sin(phi)
    s = 0.5 * (1 + sz)
    p2 = (1 - s) * np.sqrt(1 - p1 * p1) + s * p2
    p3 = np.sqrt(np.maximum(0.0, 1 - p1 * p1 - p2 * p2))
    # Stretched-space normal p1·(0, 1, 0) + p2·T2 + p3·V, unstretched.
    nx = alpha * (p2 * t2x + p3 * sx)
    ny = alpha * p1
    nz = np.maximum(0.0, p2 * t2z + p3 * sz)
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    v_h = v[0] * nx + v[2] * nz
    cos_l = 2 * v_h * nz - mu
    # f_s (n·l) / pdf_vndf(l) = F G1(l): the weight of one sample.
    weight = np.where(cos_l > 0, smith_g1(np.maximum(cos_l, 1e-12), a2), 0.0)
    c5 = (1 - np.clip(v_h, 0, 1)) ** 5
    return (weight * (1 - c5)).mean(1), (weight * c5).mean(1)


class Tables:
    """A, B and Ē_d, with pure-Python lookups (the BSDF runs one direction at a time)."""

    def __init__(self, samples=TABLE_SAMPLES, size=TABLE_SIZE):
        mus, roughnesses = table_nodes(size)
        self.size = size
        self.a = np.zeros((size, size))
        self.b = np.zeros((size, size))
        for j, r in enumerate(roughnesses):
            self.a[:, j], self.b[:, j] = albedo_terms(mus, r, samples)
        # Ē_d at each r node: 2 ∫ E_d μ dμ of the interpolant, piecewise linear in x = √μ
        # between the nodes i/(size − 1) (the first node's value is that at μ = 10⁻³), i.e.
        # 4 ∫ E_d x³ dx: a quartic per segment, exact with 3-point Gauss–Legendre.
        e_d = F0_DIELECTRIC * self.a + self.b
        x = np.arange(size) / (size - 1)
        h = x[1] - x[0]
        total = np.zeros(size)
        for t, w in ((-math.sqrt(0.6), 5 / 9), (0.0, 8 / 9), (math.sqrt(0.6), 5 / 9)):
            xs = x[:-1] + 0.5 * h * (1 + t)
            f = e_d[:-1] + (e_d[1:] - e_d[:-1]) * (0.5 * (1 + t))
            total += (w * 0.5 * h * f * (xs ** 3)[:, None]).sum(0)
        self.ebar_d = 4 * total
        self._a = self.a.ravel().tolist()
        self._b = self.b.ravel().tolist()
        self._ebar = self.ebar_d.tolist()

    def _cell(self, x):
        x = min(max(x, 0.0), 1.0) * (self.size - 1)
        i = min(int(x), self.size - 2)
        return i, x - i

    def ab(self, mu, roughness):
        """(A, B) at view cosine mu and (clamped) roughness, bilinear in (√μ, r)."""
        i, fx = self._cell(math.sqrt(min(max(mu, 0.0), 1.0)))
        j, fy = self._cell(roughness)
        k = i * self.size + j
        w00, w01, w10, w11 = (1 - fx) * (1 - fy), (1 - fx) * fy, fx * (1 - fy), fx * fy
        n = self.size
        a = w00 * self._a[k] + w01 * self._a[k + 1] + w10 * self._a[k + n] + w11 * self._a[k + n + 1]
        b = w00 * self._b[k] + w01 * self._b[k + 1] + w10 * self._b[k + n] + w11 * self._b[k + n + 1]
        return a, b

    def e_d(self, mu, roughness):
        a, b = self.ab(mu, roughness)
        return F0_DIELECTRIC * a + b

    def ebar_d_at(self, roughness):
        """Ē_d of the bilinear interpolant: linear in r between the nodes' exact integrals."""
        j, fy = self._cell(roughness)
        return (1 - fy) * self._ebar[j] + fy * self._ebar[j + 1]


_TABLES = None


def tables():
    """The tables at the default size and sample count, computed once per process (~1 s)."""
    global _TABLES
    if _TABLES is None:
        _TABLES = Tables()
    return _TABLES


# ---------------------------------------------------------------------------------------------
# The BSDF in its shading frame (pure Python, one direction at a time)

class Material:
    """f for one surface; directions are 3-tuples in the shading frame with wi.z > 0."""

    def __init__(self, base, metallic, roughness, table=None):
        self.table = table or tables()
        m = min(max(metallic, 0.0), 1.0)
        self.roughness = max(min(roughness, 1.0), MIN_ROUGHNESS)
        self.alpha = self.roughness * self.roughness
        self.a2 = self.alpha * self.alpha
        self.f0 = tuple(F0_DIELECTRIC + (c - F0_DIELECTRIC) * m for c in base)
        self.diffuse = tuple((1 - m) * c for c in base)
        self.diffuse_scale = 1.0 / (math.pi * (1.0 - self.table.ebar_d_at(self.roughness)))
        self.lum_f0 = luminance(self.f0)
        self.lum_diffuse = luminance(self.diffuse)

    def _lambda_term(self, cos):
        """√(a2 + (1 − a2) cos²): G1(x) = 2 cos / (cos + this)."""
        return math.sqrt(self.a2 + (1 - self.a2) * cos * cos)

    def p_diffuse(self, cos_v):
        a, b = self.table.ab(cos_v, self.roughness)
        diffuse = self.lum_diffuse * (1 - (F0_DIELECTRIC * a + b))
        total = diffuse + self.lum_f0 * a + b
        return diffuse / total if total > 0 else 0.0

    def eval_pdf(self, wi, wo):
        """(f·(n·wo) as an RGB tuple, the sampling pdf of wo in solid angle)."""
        cos_v, cos_l = wi[2], wo[2]
        if cos_v <= 0 or cos_l <= 0:
            return (0.0, 0.0, 0.0), 0.0
        hx, hy, hz = wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]
        norm = math.sqrt(hx * hx + hy * hy + hz * hz)
        cos_h = hz / norm
        v_h = min(max((wi[0] * hx + wi[1] * hy + wi[2] * hz) / norm, 0.0), 1.0)
        t = cos_h * cos_h * (self.a2 - 1) + 1
        d = self.a2 / (math.pi * t * t)
        lam_v = self._lambda_term(cos_v)
        # G / (4 (n·l)(n·v)) = 1 / ((n·l + Λl)(n·v + Λv)) with Λx = √(a2 + (1 − a2)(n·x)²).
        vis = 1.0 / ((cos_l + self._lambda_term(cos_l)) * (cos_v + lam_v))
        c5 = (1 - v_h) ** 5
        e_l = self.table.e_d(cos_l, self.roughness)
        e_v = self.table.e_d(cos_v, self.roughness)
        diffuse = (1 - e_l) * (1 - e_v) * self.diffuse_scale
        f = tuple(
            (kd * diffuse + (f0 + (1 - f0) * c5) * d * vis) * cos_l
            for kd, f0 in zip(self.diffuse, self.f0)
        )
        p_d = self.p_diffuse(cos_v)
        # Visible-normal density of h over 4 (v·h): D G1(v) (v·h)/(n·v) / (4 v·h).
        pdf_s = d / (2 * (cos_v + lam_v))
        return f, p_d * cos_l / math.pi + (1 - p_d) * pdf_s

    def sample(self, wi, u0, u1, u2):
        """A direction wo and whether it came from the diffuse lobe (None: below the surface)."""
        if u0 < self.p_diffuse(wi[2]):
            r = math.sqrt(u1)
            phi = 2 * math.pi * u2
            return (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(1 - u1, 0.0))), True
        h = self.sample_visible_normal(wi, u1, u2)
        w_h = 2 * (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2])
        wo = (w_h * h[0] - wi[0], w_h * h[1] - wi[1], w_h * h[2] - wi[2])
        return (wo if wo[2] > 0 else None), False

    def sample_visible_normal(self, wi, u1, u2):
        """Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (JCGT 7(4))."""
        a = self.alpha
        vx, vy, vz = a * wi[0], a * wi[1], wi[2]
        norm = math.sqrt(vx * vx + vy * vy + vz * vz)
        vx, vy, vz = vx / norm, vy / norm, vz / norm
        lensq = vx * vx + vy * vy
        if lensq > 0:
            inv = 1 / math.sqrt(lensq)
            t1 = (-vy * inv, vx * inv, 0.0)
        else:
            t1 = (1.0, 0.0, 0.0)
        t2 = (vy * t1[2] - vz * t1[1], vz * t1[0] - vx * t1[2], vx * t1[1] - vy * t1[0])
        r = math.sqrt(u1)
        phi = 2 * math.pi * u2
        p1, p2 = r * math.cos(phi), r * math.sin(phi)
        s = 0.5 * (1 + vz)
        p2 = (1 - s) * math.sqrt(max(1 - p1 * p1, 0.0)) + s * p2
        p3 = math.sqrt(max(0.0, 1 - p1 * p1 - p2 * p2))
        nx = a * (p1 * t1[0] + p2 * t2[0] + p3 * vx)
        ny = a * (p1 * t1[1] + p2 * t2[1] + p3 * vy)
        nz = max(0.0, p1 * t1[2] + p2 * t2[2] + p3 * vz)
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        return nx / norm, ny / norm, nz / norm


# ---------------------------------------------------------------------------------------------
# Mitsuba

def register_bsdf(mi):
    """Registers the Mitsuba BSDF plug-in "lightcast" (props r, g, b, metallic, roughness)."""

    class LightcastBSDF(mi.BSDF):
        """lightcast's material model, two-sided; see this module's docstring."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.material = Material(
                (props["r"], props["g"], props["b"]), props["metallic"], props["roughness"]
            )
            flags = (
                mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection
                | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            )
            self.m_components = [flags]
            self.m_flags = flags

        def _local(self, si, wo):
            wi = (float(si.wi[0]), float(si.wi[1]), float(si.wi[2]))
            o = (float(wo[0]), float(wo[1]), float(wo[2]))
            if wi[2] < 0:  # two-sided: the side facing the ray is the front
                wi = (wi[0], wi[1], -wi[2])
                o = (o[0], o[1], -o[2])
            return wi, o

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = mi.BSDFSample3f()
            wi = (float(si.wi[0]), float(si.wi[1]), float(si.wi[2]))
            flip = wi[2] < 0
            if flip:
                wi = (wi[0], wi[1], -wi[2])
            o, diffuse = self.material.sample(wi, float(sample1), float(sample2[0]), float(sample2[1]))
            if o is None:
                return bs, mi.Color3f(0.0)
            f, pdf = self.material.eval_pdf(wi, o)
            if pdf <= 0:
                return bs, mi.Color3f(0.0)
            bs.wo = mi.Vector3f(o[0], o[1], -o[2] if flip else o[2])
            bs.pdf = pdf
            bs.eta = 1.0
            bs.sampled_type = int(
                mi.BSDFFlags.DiffuseReflection if diffuse else mi.BSDFFlags.GlossyReflection
            )
            bs.sampled_component = 0
            return bs, mi.Color3f(f[0] / pdf, f[1] / pdf, f[2] / pdf)

        def eval(self, ctx, si, wo, active=True):
            return mi.Color3f(*self.material.eval_pdf(*self._local(si, wo))[0])

        def pdf(self, ctx, si, wo, active=True):
            return self.material.eval_pdf(*self._local(si, wo))[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            f, pdf = self.material.eval_pdf(*self._local(si, wo))
            return mi.Color3f(*f), pdf

        def to_string(self):
            m = self.material
            return "LightcastBSDF[f0=%r, diffuse=%r, roughness=%r]" % (m.f0, m.diffuse, m.roughness)

    mi.register_bsdf("lightcast", lambda props: LightcastBSDF(props))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--samples", type=int, default=TABLE_SAMPLES, help="quadrature points per entry")
    args = ap.parse_args()
    t = Tables(args.samples)
    mus, roughnesses = table_nodes()
    json.dump(
        {
            "mu": mus.tolist(), "roughness": roughnesses.tolist(), "samples": args.samples,
            "A": t.a.tolist(), "B": t.b.tolist(), "Ebar_d": t.ebar_d.tolist(),
        },
        sys.stdout, indent=1,
    )


if __name__ == "__main__":
    main()
