// Seam smoothing (Sato et al., "Example-based Synthesis of Turbulence by Flow Field Style Transfer", section 3.3):
// band geometry, CGNR E-step, boundary-patch M-step.
#include <turb/Seams.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>

namespace turb {

PatchLayout PatchLayout::covering(const CoordBBox& box, int size)
{
    if (size < 1) throw ValueError("local patch size must be >= 1");
    PatchLayout l;
    l.origin = box.min();
    l.size = size;
    l.flat = isFlat(box);
    const Coord d = box.dim();
    l.count = Coord((d.x() + size - 1) / size, (d.y() + size - 1) / size, (d.z() + size - 1) / size);
    return l;
}

std::vector<uint8_t> seamBand(
    const CoordBBox& box, const PatchLayout& layout, const std::vector<uint8_t>& active, int bandWidth)
{
    if (bandWidth < 1) throw ValueError("seam band width must be >= 1");
    const Coord d = box.dim();
    std::vector<uint8_t> band(size_t(d.x()) * size_t(d.y()) * size_t(d.z()), 0);
    const int B = layout.size;
    parallelFor(size_t(d.x()), 1, [&](size_t x0, size_t x1) {
        for (size_t xi = x0; xi < x1; ++xi)
            for (int y = 0; y < d.y(); ++y)
                for (int z = 0; z < d.z(); ++z) {
                    const Coord v = box.min() + Coord(int(xi), y, z);
                    const Coord P = layout.patchOf(v);
                    const bool here = active[layout.patchIndex(P)] != 0;
                    bool in = false;
                    for (int a = 0; a < 3 && !in; ++a) {
                        const int w = v[a] - layout.origin[a] - P[a] * B; // position inside the patch
                        // Near the lower border (with patch P - e_a) or the upper one (with P + e_a).
                        for (int side : {-1, 1}) {
                            const bool near = side < 0 ? (w < bandWidth) : (w >= B - bandWidth);
                            Coord Q = P;
                            Q[a] += side;
                            if (!near || Q[a] < 0 || Q[a] >= layout.count[a]) continue;
                            if (here || active[layout.patchIndex(Q)]) in = true;
                        }
                    }
                    band[(size_t(xi) * size_t(d.y()) + size_t(y)) * size_t(d.z()) + size_t(z)] = in;
                }
    });
    return band;
}

namespace {

// The least-squares system over R = Ω dilated by one voxel (every row touching Ω lives there).
class SeamSystem
{
public:
    SeamSystem(const VectorField& X, const std::vector<uint8_t>& omega, float gamma, const VectorField* base = nullptr,
        float baseScale = 1.0f)
        : mBox(X.bbox()), mDim(X.bbox().dim()), mSqrtGamma(std::sqrt(std::max(0.0f, gamma))), mBase(base),
          mBaseScale(baseScale), mAxes(isFlat(X.bbox()) ? 2 : 3)
    {
        const size_t n = X.size();
        mCompact.assign(n, -1);
        std::vector<uint8_t> inR(n, 0);
        for (size_t i = 0; i < n; ++i) {
            if (!omega[i]) continue;
            inR[i] = 1;
            const Coord c = X.coordOf(i);
            for (int f = 0; f < 6; ++f) {
                const Coord q = c + step(f);
                if (mBox.isInside(q)) inR[X.offset(q.x(), q.y(), q.z())] = 1;
            }
        }
        for (size_t i = 0; i < n; ++i)
            if (inR[i]) {
                mCompact[i] = int(mLinear.size());
                mLinear.push_back(i);
            }
        const size_t m = mLinear.size();
        mOmega.assign(m, 0);
        for (int f = 0; f < 6; ++f) mNb[f].assign(m, -1);
        mInBox.assign(m * 6, 0);
        parallelFor(m, 4096, [&](size_t b, size_t e) {
            for (size_t r = b; r < e; ++r) {
                const size_t i = mLinear[r];
                mOmega[r] = omega[i];
                const Coord c = X.coordOf(i);
                for (int f = 0; f < 6; ++f) {
                    const Coord q = c + step(f);
                    if (!mBox.isInside(q)) continue;
                    mInBox[r * 6 + size_t(f)] = 1;
                    mNb[f][r] = mCompact[X.offset(q.x(), q.y(), q.z())];
                }
            }
        });
        for (size_t r = 0; r < m; ++r)
            if (mOmega[r]) mUnknowns.push_back(int(r));
        mTargets.assign(m * 3, Vec3f(0.0f));
        precompute();
    }

    // Row flags, stencils and the A^T gather coefficients are fixed for the band: compute them once
    // so the CG loop is plain array arithmetic.
    void precompute()
    {
        const size_t m = rows();
        mFlags.assign(m, 0);
        mLo.assign(m * 3, -1);
        mHi.assign(m * 3, -1);
        mInv.assign(m * 3, 0.0f);
        parallelFor(m, 4096, [&](size_t b, size_t e) {
            for (size_t r = b; r < e; ++r) {
                uint8_t fl = 0;
                for (int a = 0; a < 3; ++a) {
                    if (edgeRow(r, a)) fl |= uint8_t(1u << a);
                    int lo, hi;
                    float inv;
                    stencil(r, a, lo, hi, inv);
                    mLo[r * 3 + size_t(a)] = lo;
                    mHi[r * 3 + size_t(a)] = hi;
                    mInv[r * 3 + size_t(a)] = inv;
                }
                if (divRow(r)) fl |= 8u;
                mFlags[r] = fl;
            }
        });
        const size_t nu = mUnknowns.size();
        mEdgeMask.assign(nu, 0);
        parallelFor(nu, 4096, [&](size_t b, size_t e) {
            for (size_t u = b; u < e; ++u) {
                const size_t r = size_t(mUnknowns[u]);
                uint8_t mask = 0;
                for (int a = 0; a < 3; ++a) {
                    const int lo = mNb[2 * a][r];
                    if (lo >= 0 && (mFlags[size_t(lo)] & (1u << a))) mask |= uint8_t(1u << a);
                    if (mFlags[r] & (1u << a)) mask |= uint8_t(8u << a);
                }
                mEdgeMask[u] = mask;
            }
        });
        mDivRows.clear();
        for (size_t r = 0; r < m; ++r)
            if (mFlags[r] & 8u) mDivRows.push_back(int(r));
        // Coefficients of the central differences are +-1/span, span 1 or 2: twice each is an exact small integer.
        mGatherHalves.assign(nu * 9, 0);
        parallelFor(nu, 2048, [&](size_t b, size_t e) {
            for (size_t u = b; u < e; ++u) {
                const int r = mUnknowns[u];
                for (int a = 0; a < 3; ++a) {
                    const int cands[3] = {mNb[2 * a][size_t(r)], mNb[2 * a + 1][size_t(r)], r};
                    for (int k = 0; k < 3; ++k) {
                        const int v = cands[k];
                        if (v < 0 || !(mFlags[size_t(v)] & 8u)) continue;
                        float coef = 0.0f;
                        if (mHi[size_t(v) * 3 + size_t(a)] == r) coef += mInv[size_t(v) * 3 + size_t(a)];
                        if (mLo[size_t(v) * 3 + size_t(a)] == r) coef -= mInv[size_t(v) * 3 + size_t(a)];
                        mGatherHalves[u * 9 + size_t(a * 3 + k)] = int8_t(std::lround(2.0f * coef));
                    }
                }
            }
        });
    }

    // Sum over the divergence rows whose stencil reads component a of unknown u (row r) of coefficient x d[row]:
    // the rows are r's neighbours along a and r itself.
    float gatherDiv(size_t u, size_t r, int a, const std::vector<float>& d) const
    {
        const int8_t* h = &mGatherHalves[u * 9 + size_t(a * 3)];
        float g = 0.0f;
        if (h[0]) g += 0.5f * float(h[0]) * d[size_t(mNb[2 * a][r])];
        if (h[1]) g += 0.5f * float(h[1]) * d[size_t(mNb[2 * a + 1][r])];
        if (h[2]) g += 0.5f * float(h[2]) * d[r];
        return g;
    }

    static Coord step(int f)
    {
        static const Coord s[6] = {
            Coord(-1, 0, 0), Coord(1, 0, 0), Coord(0, -1, 0), Coord(0, 1, 0), Coord(0, 0, -1), Coord(0, 0, 1)};
        return s[f];
    }

    size_t rows() const { return mLinear.size(); }
    size_t unknowns() const { return mUnknowns.size(); }
    size_t linear(size_t r) const { return mLinear[r]; }
    bool inOmega(size_t r) const { return mOmega[r] != 0; }
    int compactOf(size_t lin) const { return mCompact[lin]; }
    std::vector<Vec3f>& targets() { return mTargets; }

    // Edge row (r, a) exists when r + e_a is in the box and an endpoint is unknown.
    bool edgeRow(size_t r, int a) const
    {
        const int q = mNb[2 * a + 1][r];
        return mInBox[r * 6 + size_t(2 * a + 1)] && q >= 0 && (mOmega[r] || mOmega[size_t(q)]);
    }
    // Div row r exists when its central stencil touches an unknown.
    bool divRow(size_t r) const
    {
        for (int f = 0; f < 6; ++f) {
            const int q = mNb[f][r];
            if (q >= 0 && mOmega[size_t(q)]) return true;
        }
        return false;
    }
    // Central difference along a, one-sided at the box faces: (x[hi] - x[lo]) / span.
    void stencil(size_t r, int a, int& lo, int& hi, float& inv) const
    {
        const bool hasLo = mInBox[r * 6 + size_t(2 * a)], hasHi = mInBox[r * 6 + size_t(2 * a + 1)];
        lo = hasLo ? mNb[2 * a][r] : int(r);
        hi = hasHi ? mNb[2 * a + 1][r] : int(r);
        const int span = int(hasLo) + int(hasHi);
        inv = span ? 1.0f / float(span) : 0.0f;
    }

    // Residual rows of the full field: targets - grad X on edges, -sqrt(gamma) div X on div rows.
    // Values outside R are read from the dense field directly.
    void residual(const VectorField& X, std::vector<Vec3f>& se, std::vector<float>& sd, std::vector<Vec3f>& sb,
        std::vector<Vec3f>& sv) const
    {
        const size_t m = rows();
        se.assign(m * 3, Vec3f(0.0f));
        sd.assign(m, 0.0f);
        sb.assign(mCells.size(), Vec3f(0.0f));
        sv.assign(mValueCoef.size(), Vec3f(0.0f));
        const Vec3f* x = X.data();
        // Value rows: sqrt(mu_u) * (anchor - X) at the unknowns that have one.
        for (size_t u = 0; u < mValueCoef.size(); ++u)
            sv[u] = (mAnchor[u] - x[mLinear[size_t(mUnknowns[u])]]) * mValueCoef[u];
        // Box rows: sqrt(nu) * (target mean - mean of X over the coarse cell, fixed voxels included).
        parallelFor(mCells.size(), 256, [&](size_t b, size_t e) {
            for (size_t c = b; c < e; ++c) sb[c] = (mBoxTarget[c] - cellSum(X, c)) * mBoxCoef;
        });
        parallelFor(m, 4096, [&](size_t b, size_t e) {
            for (size_t r = b; r < e; ++r) {
                const size_t i = mLinear[r];
                const Coord c = X.coordOf(i);
                for (int a = 0; a < 3; ++a) {
                    if (!edgeRow(r, a)) continue;
                    const Coord q = c + step(2 * a + 1);
                    se[r * 3 + size_t(a)] = mTargets[r * 3 + size_t(a)] - (x[X.offset(q.x(), q.y(), q.z())] - x[i]);
                }
                if (!divRow(r)) continue;
                float div = 0.0f;
                for (int a = 0; a < 3; ++a) {
                    const bool hasLo = mInBox[r * 6 + size_t(2 * a)], hasHi = mInBox[r * 6 + size_t(2 * a + 1)];
                    const Coord lo = hasLo ? c + step(2 * a) : c, hi = hasHi ? c + step(2 * a + 1) : c;
                    const int span = int(hasLo) + int(hasHi);
                    if (span) {
                        const size_t ih = X.offset(hi.x(), hi.y(), hi.z()), il = X.offset(lo.x(), lo.y(), lo.z());
                        float dv = x[ih][a] - x[il][a];
                        if (mBase) dv += (mBase->data()[ih][a] - mBase->data()[il][a]) * mBaseScale;
                        div += dv / float(span);
                    }
                }
                sd[r] = -mSqrtGamma * div;
            }
        });
    }

    // g = A^T (se, sd, sb, sv), gathered at the unknowns (zero elsewhere).
    void applyAt(const std::vector<Vec3f>& se, const std::vector<float>& sd, const std::vector<Vec3f>& sb,
        const std::vector<Vec3f>& sv, std::vector<Vec3f>& g) const
    {
        // Only the unknowns' entries are written; the rest stay zero from the first call (solve() passes the same g).
        if (g.size() != rows()) g.assign(rows(), Vec3f(0.0f));
        parallelFor(mUnknowns.size(), 2048, [&](size_t b, size_t e) {
            for (size_t u = b; u < e; ++u) {
                const size_t r = size_t(mUnknowns[u]);
                const uint8_t mask = mEdgeMask[u];
                Vec3f acc(0.0f);
                for (int a = 0; a < mAxes; ++a) {
                    // Edge (r - e_a, r) has +1 on x[r]; edge (r, r + e_a) has -1.
                    if (mask & (1u << a)) acc += se[size_t(mNb[2 * a][r]) * 3 + size_t(a)];
                    if (mask & (8u << a)) acc -= se[r * 3 + size_t(a)];
                    // Divergence rows whose stencil uses x[r][a].
                    acc[a] += mSqrtGamma * gatherDiv(u, r, a, sd);
                }
                if (!mCells.empty()) acc += sb[size_t(mCellOf[u])] * mBoxCoef;
                if (!sv.empty()) acc += sv[u] * mValueCoef[u];
                g[r] = acc;
            }
        });
    }

    // Np = A^T A p for p over R (zero outside Ω), and p . Np = |A p|^2: the divergence rows and cell sums of A p
    // first, then per unknown its edge rows (the Laplacian of the edges that exist), the divergence rows that read
    // it, its cell's box row and its value row. The edge rows' values of A p are never stored: a CG iteration streams
    // through about half the memory that A p followed by A^T did (E-steps of the Blender paper pair's frames 29-30,
    // 7e5-voxel bands: 2.7 -> 1.6 s and 1.9 -> 1.1 s, with the compact gather coefficients below).
    double applyNormal(
        const std::vector<Vec3f>& p, std::vector<float>& d, std::vector<Vec3f>& cells, std::vector<Vec3f>& Np) const
    {
        if (d.size() != rows()) d.assign(rows(), 0.0f); // rows without a divergence row stay zero
        cells.resize(mCells.size());
        if (Np.size() != rows()) Np.assign(rows(), Vec3f(0.0f));
        parallelFor(mDivRows.size(), 4096, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
                const size_t r = size_t(mDivRows[i]);
                float div = 0.0f;
                for (int a = 0; a < mAxes; ++a) {
                    const int lo = mLo[r * 3 + size_t(a)], hi = mHi[r * 3 + size_t(a)];
                    const float vh = hi >= 0 ? p[size_t(hi)][a] : 0.0f, vl = lo >= 0 ? p[size_t(lo)][a] : 0.0f;
                    div += (vh - vl) * mInv[r * 3 + size_t(a)];
                }
                d[r] = mSqrtGamma * div;
            }
        });
        const float box2 = mBoxCoef * mBoxCoef;
        parallelFor(mCells.size(), 256, [&](size_t b, size_t e) {
            for (size_t c = b; c < e; ++c) {
                Vec3f sum(0.0f);
                for (int k = mCellStart[c]; k < mCellStart[c + 1]; ++k) sum += p[size_t(mCellMembers[size_t(k)])];
                cells[c] = sum * box2;
            }
        });
        return parallelSum(mUnknowns.size(), 2048, [&](size_t b, size_t e) {
            double pNp = 0.0;
            for (size_t u = b; u < e; ++u) {
                const size_t r = size_t(mUnknowns[u]);
                const Vec3f pr = p[r];
                const uint8_t mask = mEdgeMask[u];
                Vec3f acc(0.0f);
                for (int a = 0; a < mAxes; ++a) {
                    if (mask & (1u << a)) acc += pr - p[size_t(mNb[2 * a][r])];
                    if (mask & (8u << a)) acc += pr - p[size_t(mNb[2 * a + 1][r])];
                    acc[a] += mSqrtGamma * gatherDiv(u, r, a, d);
                }
                if (!mCells.empty()) acc += cells[size_t(mCellOf[u])];
                if (!mValueCoef.empty()) acc += pr * (mValueCoef[u] * mValueCoef[u]);
                Np[r] = acc;
                pNp += double(pr.dot(acc));
            }
            return pNp;
        });
    }

    double dotUnknowns(const std::vector<Vec3f>& a, const std::vector<Vec3f>& b) const
    {
        return parallelSum(mUnknowns.size(), 4096, [&](size_t s, size_t e) {
            double acc = 0.0;
            for (size_t u = s; u < e; ++u) {
                const size_t r = size_t(mUnknowns[u]);
                acc += double(a[r].dot(b[r]));
            }
            return acc;
        });
    }

    double rowNormSq(const std::vector<Vec3f>& se, const std::vector<float>& sd, const std::vector<Vec3f>& sb,
        const std::vector<Vec3f>& sv) const
    {
        double boxes = 0.0;
        for (const auto& v : sb) boxes += double(v.lengthSqr());
        for (const auto& v : sv) boxes += double(v.lengthSqr());
        return boxes + parallelSum(rows(), 4096, [&](size_t s, size_t e) {
            double acc = 0.0;
            for (size_t r = s; r < e; ++r)
                acc += double(se[r * 3].lengthSqr() + se[r * 3 + 1].lengthSqr() + se[r * 3 + 2].lengthSqr()) +
                       double(sd[r]) * double(sd[r]);
            return acc;
        });
    }

    // Adds one row per coarse cell (factor^3 fine voxels, cells at multiples of factor) that holds an
    // unknown: sqrt(nu) * (mean(X) - keep * mean(X on entry)) over the cell. The seams and the divergence
    // term then move detail within cells without adding coarse motion (lf_err), and no separate,
    // divergence-adding correction has to take out what the solve would otherwise put there.
    void enableBoxRows(const VectorField& X, int factor, float weight, float keep)
    {
        mBoxF = factor;
        const int cell = factor * factor * (isFlat(mBox) ? 1 : factor); // voxels per coarse cell (f^2 in 2D)
        mBoxCoef = std::sqrt(std::max(0.0f, weight) * float(cell)) / float(cell);
        std::vector<std::pair<Coord, int>> keyed;
        keyed.reserve(mUnknowns.size());
        const int flatZ = isFlat(mBox) ? 1 : factor;
        for (size_t u = 0; u < mUnknowns.size(); ++u) {
            const Coord c = coordOfLinear(mLinear[size_t(mUnknowns[u])]);
            keyed.emplace_back(Coord(floorDiv(c.x(), factor), floorDiv(c.y(), factor), floorDiv(c.z(), flatZ)), int(u));
        }
        std::sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) {
            if (a.first != b.first) return a.first < b.first;
            return a.second < b.second;
        });
        mCells.clear();
        mCellStart.clear();
        mCellMembers.clear();
        mCellOf.assign(mUnknowns.size(), 0);
        for (size_t i = 0; i < keyed.size(); ++i) {
            if (i == 0 || keyed[i].first != keyed[i - 1].first) {
                mCells.push_back(keyed[i].first);
                mCellStart.push_back(int(mCellMembers.size()));
            }
            mCellOf[size_t(keyed[i].second)] = int(mCells.size()) - 1;
            mCellMembers.push_back(mUnknowns[size_t(keyed[i].second)]);
        }
        mCellStart.push_back(int(mCellMembers.size()));
        // Targets as sums over each cell (the rows' unit), from X as it enters the solve.
        mBoxTarget.assign(mCells.size(), Vec3f(0.0f));
        if (keep != 0.0f)
            parallelFor(mCells.size(), 256, [&](size_t b, size_t e) {
                for (size_t c = b; c < e; ++c) mBoxTarget[c] = cellSum(X, c) * keep;
            });
    }

    // The sum of X over box row c's coarse cell (fixed voxels included), in the box rows' unit.
    Vec3f cellSum(const VectorField& X, size_t c) const
    {
        CoordBBox cb = refineBox(CoordBBox(mCells[c], mCells[c]), mBoxF);
        if (isFlat(mBox))
            cb = CoordBBox(
                Coord(cb.min().x(), cb.min().y(), mCells[c].z()), Coord(cb.max().x(), cb.max().y(), mCells[c].z()));
        cb.intersect(mBox);
        Vec3f sum(0.0f);
        for (int i = cb.min().x(); i <= cb.max().x(); ++i)
            for (int j = cb.min().y(); j <= cb.max().y(); ++j)
                for (int k = cb.min().z(); k <= cb.max().z(); ++k) sum += X.data()[X.offset(i, j, k)];
        return sum;
    }

    // Adds one value row per unknown u with weight mu(u) > 0: sqrt(mu) * (X - anchor), so the solve
    // changes the carried detail no more than the seams, box means and divergence need (tcoh measures
    // that change in values, which the gradient rows alone do not see).
    template<typename WeightFn>
    void enableValueRows(const VectorField& anchor, WeightFn&& mu)
    {
        mValueCoef.assign(mUnknowns.size(), 0.0f);
        mAnchor.assign(mUnknowns.size(), Vec3f(0.0f));
        for (size_t u = 0; u < mUnknowns.size(); ++u) {
            const size_t lin = mLinear[size_t(mUnknowns[u])];
            mValueCoef[u] = std::sqrt(std::max(0.0f, mu(coordOfLinear(lin))));
            mAnchor[u] = anchor.data()[lin];
        }
    }

    Coord coordOfLinear(size_t n) const
    {
        const int k = int(n % size_t(mDim.z()));
        const size_t r = n / size_t(mDim.z());
        return mBox.min() + Coord(int(r / size_t(mDim.y())), int(r % size_t(mDim.y())), k);
    }

    // CG on the normal equations A^T A delta = A^T s (CGNR): the same iterates as CGLS in exact arithmetic and the same
    // stopping test, the relative normal residual |A^T s| / |A^T s0|, tracked by its recurrence.
    SeamIteration solve(VectorField& X, int maxIterations, double tolerance) const
    {
        SeamIteration out;
        std::vector<Vec3f> se, sb, sv, cells, r, p, Np, delta(rows(), Vec3f(0.0f));
        std::vector<float> sd, d;
        residual(X, se, sd, sb, sv);
        applyAt(se, sd, sb, sv, r);
        p = r;
        double rr = dotUnknowns(r, r);
        const double rr0 = rr;
        int it = 0;
        if (rr0 > 0.0) {
            for (; it < maxIterations; ++it) {
                if (std::sqrt(rr / rr0) <= tolerance) break;
                const double pNp = applyNormal(p, d, cells, Np);
                if (!(pNp > 0.0)) break;
                const float alpha = float(rr / pNp);
                const double rrNew = parallelSum(mUnknowns.size(), 4096, [&](size_t b, size_t e) {
                    double acc = 0.0;
                    for (size_t u = b; u < e; ++u) {
                        const size_t k = size_t(mUnknowns[u]);
                        delta[k] += p[k] * alpha;
                        r[k] -= Np[k] * alpha;
                        acc += double(r[k].dot(r[k]));
                    }
                    return acc;
                });
                const float beta = float(rrNew / rr);
                rr = rrNew;
                parallelFor(mUnknowns.size(), 4096, [&](size_t b, size_t e) {
                    for (size_t u = b; u < e; ++u) {
                        const size_t k = size_t(mUnknowns[u]);
                        p[k] = r[k] + p[k] * beta;
                    }
                });
            }
        }
        for (int u : mUnknowns) X.data()[mLinear[size_t(u)]] += delta[size_t(u)];
        out.cgIterations = it;
        out.cgResidual = rr0 > 0.0 ? std::sqrt(rr / rr0) : 0.0;
        out.energy = energy(X);
        return out;
    }

    // The E-step by a library solver, for measuring against solve(): the rows residual() and applyNormal() define,
    // assembled once as a sparse matrix over the unknowns' components, and solved by Eigen's
    // LeastSquaresConjugateGradient (CG on the normal equations with the diagonal preconditioner, in double).
    // Its stopping test is the same relative normal residual |A^T r| / |A^T r0|, checked after each step.
    SeamIteration solveLeastSquares(VectorField& X, int maxIterations, double tolerance)
    {
        if (!mLeastSquares) mLeastSquares = assembleLeastSquares();
        LeastSquares& ls = *mLeastSquares;
        std::vector<Vec3f> se, sb, sv;
        std::vector<float> sd;
        residual(X, se, sd, sb, sv);
        const Eigen::VectorXd b = leastSquaresRhs(ls, se, sd, sb, sv);
        ls.solver.setMaxIterations(std::max(0, maxIterations));
        ls.solver.setTolerance(tolerance);
        const Eigen::VectorXd delta = ls.solver.solve(b);
        for (size_t u = 0; u < mUnknowns.size(); ++u)
            X.data()[mLinear[size_t(mUnknowns[u])]] += Vec3f(float(delta[Eigen::Index(3 * u)]),
                float(delta[Eigen::Index(3 * u + 1)]), float(delta[Eigen::Index(3 * u + 2)]));
        SeamIteration out;
        // Eigen does not count the step after which it stops converged; count matrix products, as solve() does.
        out.cgIterations = int(ls.solver.iterations());
        if (ls.solver.info() == Eigen::Success &&
            !(out.cgIterations == 0 && (ls.A.transpose() * b).squaredNorm() == 0.0))
            ++out.cgIterations;
        out.cgResidual = ls.solver.error();
        out.energy = energy(X);
        return out;
    }

    double energy(const VectorField& X) const
    {
        std::vector<Vec3f> se, sb, sv;
        std::vector<float> sd;
        residual(X, se, sd, sb, sv);
        return rowNormSq(se, sd, sb, sv);
    }

private:
    // The explicit form of the least-squares system, for solveLeastSquares. Rows in this order: per row voxel
    // its edge rows (axis a, then component) and its divergence row; then the box rows (cell, component); then
    // the value rows with a non-zero weight (unknown, component). Column 3u + c is component c of unknown u.
    using SparseRows = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;
    struct LeastSquares
    {
        SparseRows A;
        std::vector<Eigen::Index> voxelRow; // per row voxel: its first row (rows() + 1 entries)
        Eigen::LeastSquaresConjugateGradient<SparseRows> solver;
    };
    // The rows of one row voxel, at most 3 edge rows per axis and a divergence row of up to 6 entries.
    struct VoxelRows
    {
        int count = 0;
        int size[10] = {};
        int col[10][6];
        double value[10][6];
        void add(int col0, double v)
        {
            col[count][size[count]] = col0;
            value[count][size[count]++] = v;
        }
    };

    // Row voxel r's rows, as residual() evaluates them (columns of fixed voxels left out).
    void rowsOf(size_t r, const std::vector<int>& unknownOf, VoxelRows& out) const
    {
        out.count = 0;
        const int self = unknownOf[r];
        for (int a = 0; a < 3; ++a) {
            if (!(mFlags[r] & (1u << a))) continue;
            const int q = unknownOf[size_t(mNb[2 * a + 1][r])];
            for (int c = 0; c < 3; ++c, ++out.count) {
                out.size[out.count] = 0;
                if (self >= 0) out.add(3 * self + c, -1.0); // q follows r in the compact order: columns sorted
                if (q >= 0) out.add(3 * q + c, 1.0);
            }
        }
        if (!(mFlags[r] & 8u)) return;
        out.size[out.count] = 0;
        for (int a = 0; a < 3; ++a) {
            const float inv = mInv[r * 3 + size_t(a)];
            if (inv == 0.0f) continue;
            const int lo = mLo[r * 3 + size_t(a)], hi = mHi[r * 3 + size_t(a)];
            if (lo >= 0 && unknownOf[size_t(lo)] >= 0)
                out.add(3 * unknownOf[size_t(lo)] + a, -double(mSqrtGamma) * inv);
            if (hi >= 0 && unknownOf[size_t(hi)] >= 0) out.add(3 * unknownOf[size_t(hi)] + a, double(mSqrtGamma) * inv);
        }
        // Sort the (at most 6) entries by column: Eigen expects sorted inner indices.
        int* col = out.col[out.count];
        double* val = out.value[out.count];
        for (int i = 1; i < out.size[out.count]; ++i)
            for (int j = i; j > 0 && col[j - 1] > col[j]; --j) {
                std::swap(col[j - 1], col[j]);
                std::swap(val[j - 1], val[j]);
            }
        ++out.count;
    }

    std::unique_ptr<LeastSquares> assembleLeastSquares() const
    {
        const size_t m = rows(), nu = mUnknowns.size();
        std::vector<int> unknownOf(m, -1);
        for (size_t u = 0; u < nu; ++u) unknownOf[size_t(mUnknowns[u])] = int(u);
        // Rows and entries per row voxel, then their starts; the writes below go to disjoint ranges.
        std::vector<Eigen::Index> voxelRows(m + 1, 0), voxelEntries(m + 1, 0);
        parallelFor(m, 4096, [&](size_t b, size_t e) {
            VoxelRows vr;
            for (size_t r = b; r < e; ++r) {
                rowsOf(r, unknownOf, vr);
                voxelRows[r + 1] = vr.count;
                for (int k = 0; k < vr.count; ++k) voxelEntries[r + 1] += vr.size[k];
            }
        });
        for (size_t r = 0; r < m; ++r) {
            voxelRows[r + 1] += voxelRows[r];
            voxelEntries[r + 1] += voxelEntries[r];
        }
        size_t valueRows = 0;
        for (float coef : mValueCoef) valueRows += coef > 0.0f;
        const Eigen::Index nRows = voxelRows[m] + Eigen::Index(3 * (mCells.size() + valueRows));
        const Eigen::Index nnz = voxelEntries[m] + Eigen::Index(3 * (mCellMembers.size() + valueRows));
        auto ls = std::make_unique<LeastSquares>();
        SparseRows& A = ls->A;
        A.resize(nRows, Eigen::Index(3 * nu));
        A.resizeNonZeros(nnz);
        int* outer = A.outerIndexPtr();
        int* inner = A.innerIndexPtr();
        double* value = A.valuePtr();
        parallelFor(m, 4096, [&](size_t b, size_t e) {
            VoxelRows vr;
            for (size_t r = b; r < e; ++r) {
                rowsOf(r, unknownOf, vr);
                Eigen::Index row = voxelRows[r], k = voxelEntries[r];
                for (int i = 0; i < vr.count; ++i, ++row) {
                    outer[row] = int(k);
                    for (int j = 0; j < vr.size[i]; ++j, ++k) {
                        inner[k] = vr.col[i][j];
                        value[k] = vr.value[i][j];
                    }
                }
            }
        });
        Eigen::Index row = voxelRows[m], k = voxelEntries[m];
        for (size_t c = 0; c < mCells.size(); ++c)
            for (int comp = 0; comp < 3; ++comp, ++row) {
                outer[row] = int(k);
                for (int i = mCellStart[c]; i < mCellStart[c + 1]; ++i, ++k) {
                    inner[k] = 3 * unknownOf[size_t(mCellMembers[size_t(i)])] + comp;
                    value[k] = mBoxCoef;
                }
            }
        for (size_t u = 0; u < mValueCoef.size(); ++u)
            for (int comp = 0; comp < 3 && mValueCoef[u] > 0.0f; ++comp, ++row, ++k) {
                outer[row] = int(k);
                inner[k] = int(3 * u) + comp;
                value[k] = mValueCoef[u];
            }
        outer[nRows] = int(k);
        ls->voxelRow = std::move(voxelRows);
        ls->solver.compute(A);
        return ls;
    }

    // b of the explicit system: the residual rows of X (residual()'s output) in the matrix's row order.
    Eigen::VectorXd leastSquaresRhs(const LeastSquares& ls, const std::vector<Vec3f>& se, const std::vector<float>& sd,
        const std::vector<Vec3f>& sb, const std::vector<Vec3f>& sv) const
    {
        const size_t m = rows();
        Eigen::VectorXd b(ls.A.rows());
        parallelFor(m, 4096, [&](size_t bb, size_t e) {
            for (size_t r = bb; r < e; ++r) {
                Eigen::Index row = ls.voxelRow[r];
                for (int a = 0; a < 3; ++a)
                    if (mFlags[r] & (1u << a))
                        for (int c = 0; c < 3; ++c) b[row++] = se[r * 3 + size_t(a)][c];
                if (mFlags[r] & 8u) b[row] = sd[r];
            }
        });
        Eigen::Index row = ls.voxelRow[m];
        for (const Vec3f& v : sb)
            for (int c = 0; c < 3; ++c) b[row++] = v[c];
        for (size_t u = 0; u < mValueCoef.size(); ++u)
            for (int c = 0; c < 3 && mValueCoef[u] > 0.0f; ++c) b[row++] = sv[u][c];
        return b;
    }

    CoordBBox mBox;
    Coord mDim;
    float mSqrtGamma;
    const VectorField* mBase;
    float mBaseScale;
    std::vector<int> mCompact;
    std::vector<size_t> mLinear;
    std::vector<uint8_t> mOmega, mInBox;
    std::vector<int> mNb[6];
    std::vector<int> mUnknowns;
    std::vector<Vec3f> mTargets;
    std::vector<uint8_t> mFlags; // per row voxel: bits 0-2 edge rows, bit 3 div row
    std::vector<int> mLo, mHi;   // per row voxel and axis: central-difference stencil (compact, -1 outside R)
    std::vector<float> mInv;     // 1 / span of that stencil
    int mBoxF = 1;
    float mBoxCoef = 0.0f;         // sqrt(nu) / factor^3
    std::vector<Coord> mCells;     // coarse cells with box rows
    std::vector<Vec3f> mBoxTarget; // per cell: the sum of X the row pulls towards
    std::vector<int> mCellStart, mCellMembers, mCellOf;
    std::vector<uint8_t> mEdgeMask;    // per unknown: bit a = edge (r - e_a, r), bit 3 + a = (r, r + e_a)
    std::vector<int> mDivRows;         // the rows with a divergence row
    std::vector<int8_t> mGatherHalves; // per unknown, axis a, k: 2 x the coefficient of x[r][a] in the divergence row
                                       // of r's lower neighbour along a (k 0), its upper one (1), r itself (2)
    std::vector<float> mValueCoef;     // per unknown: sqrt(mu) of its value row (empty = none)
    std::vector<Vec3f> mAnchor;        // per unknown: the value that row pulls towards
    // Axes the CG products walk: a 2D box has no z edges, and its z stencils are zero (one layer, span 0).
    int mAxes;
    std::unique_ptr<LeastSquares> mLeastSquares; // solveLeastSquares' matrix, assembled on its first call
};

void loadDenseTargets(SeamSystem& sys, const std::vector<Vec3f>& dense)
{
    auto& t = sys.targets();
    for (size_t r = 0; r < sys.rows(); ++r)
        for (int a = 0; a < 3; ++a) t[r * 3 + size_t(a)] = dense[sys.linear(r) * 3 + size_t(a)];
}

} // namespace

SeamIteration solveSeamEStep(VectorField& X, const std::vector<uint8_t>& omega, const std::vector<Vec3f>& edgeTargets,
    float gamma, int maxIterations, double tolerance, SeamSolver solver)
{
    if (omega.size() != X.size() || edgeTargets.size() != 3 * X.size())
        throw ValueError("solveSeamEStep: omega / targets do not match the field");
    SeamSystem sys(X, omega, gamma);
    loadDenseTargets(sys, edgeTargets);
    if (solver == SeamSolver::EigenLscg) return sys.solveLeastSquares(X, maxIterations, tolerance);
    return sys.solve(X, maxIterations, tolerance);
}

double seamEnergy(
    const VectorField& X, const std::vector<uint8_t>& omega, const std::vector<Vec3f>& edgeTargets, float gamma)
{
    SeamSystem sys(X, omega, gamma);
    loadDenseTargets(sys, edgeTargets);
    return sys.energy(X);
}

namespace {

// A C^3 boundary patch centred on a patch border, and the Z it currently uses.
struct BoundaryPatch
{
    Coord centre;
    bool zero = false; // Z is the zero field (the neighbour carries no detail)
    Coord offset{0};   // else Z(v) = U_sh(v + offset)
};

// The boundary patches of a frame: centres on the lattice origin + k*h (h = C/2), with an index from lattice
// position k to the patch there. In 2D (a flat layout) they are C x C x 1 on the one layer: one row of centres in z.
struct BoundaryPatches
{
    int h = 1;
    Coord kCount{0};
    Coord hLo{0}, hHi{0};     // a patch covers [centre - hLo, centre + hHi]
    std::vector<int> patchId; // per lattice position k: index into `patches`, -1 = none there
    std::vector<BoundaryPatch> patches;

    size_t kIndex(const Coord& k) const
    {
        return (size_t(k.x()) * size_t(kCount.y()) + size_t(k.y())) * size_t(kCount.z()) + size_t(k.z());
    }
    CoordBBox region(const BoundaryPatch& bp) const { return CoordBBox(bp.centre - hLo, bp.centre + hHi); }
};

const Vec3f& sourceAt(const VectorField& s, const Coord& c) { return s.clamped(c.x(), c.y(), c.z()); }

// Calls fn(patch index) for every local patch that `region` overlaps, in lattice order.
template<typename Fn>
void forEachOverlappedPatch(const PatchLayout& L, const CoordBBox& region, Fn&& fn)
{
    const Coord P0 = L.patchOf(region.min()), P1 = L.patchOf(region.max());
    for (int px = std::max(0, P0.x()); px <= std::min(L.count.x() - 1, P1.x()); ++px)
        for (int py = std::max(0, P0.y()); py <= std::min(L.count.y() - 1, P1.y()); ++py)
            for (int pz = std::max(0, P0.z()); pz <= std::min(L.count.z() - 1, P1.z()); ++pz)
                fn(L.patchIndex(Coord(px, py, pz)));
}

// C, the boundary patch edge: even and dividing 2B, so that centres at spacing C/2 fall on every patch border.
int boundaryPatchEdge(const SeamProblem& problem, const SeamSettings& settings)
{
    if (!problem.sourceHigh) throw ValueError("smoothSeams: no source detail field");
    const int B = problem.layout.size;
    const int C = settings.boundaryPatch > 0 ? settings.boundaryPatch : B;
    if (C % 2 != 0 || C < 2 || (2 * B) % C != 0)
        throw ValueError("boundary patch size C must be even and divide 2*B (B = " + std::to_string(B) + ")");
    return C;
}

// Ω: the seam band, plus every voxel of the active patches the problem asks to solve whole.
std::vector<uint8_t> seamUnknowns(const VectorField& detail, const SeamProblem& problem, const SeamSettings& settings)
{
    const PatchLayout& L = problem.layout;
    std::vector<uint8_t> omega =
        seamBand(detail.bbox(), L, problem.active, L.flat ? settings.bandWidth2D : settings.bandWidth);
    if (problem.wholePatches.empty()) return omega;
    if (problem.wholePatches.size() != L.patchCount())
        throw ValueError("smoothSeams: wholePatches must hold one flag per local patch");
    parallelFor(omega.size(), 1 << 14, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) {
            const size_t p = L.patchIndex(L.patchOf(detail.coordOf(n)));
            if (problem.wholePatches[p] && problem.active[p]) omega[n] = 1;
        }
    });
    return omega;
}

// Boundary patches: centres on the lattice origin + k*(C/2), on at least one patch border, that overlap an
// active patch.
BoundaryPatches placeBoundaryPatches(const PatchLayout& L, const std::vector<uint8_t>& active, int C)
{
    const int B = L.size;
    BoundaryPatches bps;
    const int h = bps.h = C / 2;
    bps.kCount = Coord(L.count.x() * B / h + 1, L.count.y() * B / h + 1, L.flat ? 1 : L.count.z() * B / h + 1);
    bps.hLo = L.flat ? Coord(h, h, 0) : Coord(h);
    bps.hHi = L.flat ? Coord(h - 1, h - 1, 0) : Coord(h - 1);
    bps.patchId.assign(size_t(bps.kCount.x()) * size_t(bps.kCount.y()) * size_t(bps.kCount.z()), -1);
    for (int kx = 0; kx < bps.kCount.x(); ++kx)
        for (int ky = 0; ky < bps.kCount.y(); ++ky)
            for (int kz = 0; kz < bps.kCount.z(); ++kz) {
                const Coord k(kx, ky, kz);
                const Coord c = L.origin + Coord(kx * h, ky * h, kz * h);
                bool onBorder = false;
                for (int a = 0; a < 3; ++a) {
                    const int rel = c[a] - L.origin[a];
                    onBorder |= rel % B == 0 && rel > 0 && rel < L.count[a] * B;
                }
                if (!onBorder) continue;
                bool anyActive = false;
                forEachOverlappedPatch(
                    L, CoordBBox(c - bps.hLo, c + bps.hHi), [&](size_t p) { anyActive |= active[p] != 0; });
                if (!anyActive) continue;
                bps.patchId[bps.kIndex(k)] = int(bps.patches.size());
                bps.patches.push_back(BoundaryPatch{c, false, Coord(0)});
            }
    return bps;
}

// |grad X - grad Z|^2 over a boundary patch's region, Z being the zero field or U_sh at `offset`. Every other
// voxel of the region is used: the choice is among a handful of candidates.
double gradientDistance(const VectorField& detail, const VectorField& Ush, float scale, const CoordBBox& region,
    bool zero, const Coord& offset)
{
    const CoordBBox& box = detail.bbox();
    double d = 0.0;
    for (int x = region.min().x(); x <= region.max().x(); x += 2)
        for (int y = region.min().y(); y <= region.max().y(); y += 2)
            for (int z = region.min().z(); z <= region.max().z(); z += 2) {
                const Coord v(x, y, z);
                if (!box.isInside(v)) continue;
                const Vec3f xv = detail[v];
                const Vec3f zv = zero ? Vec3f(0.0f) : sourceAt(Ush, v + offset) * scale;
                for (int a = 0; a < 3; ++a) {
                    Coord q = v;
                    q[a] += 1;
                    if (q[a] > region.max()[a] || !box.isInside(q)) continue;
                    const Vec3f zq = zero ? Vec3f(0.0f) : sourceAt(Ush, q + offset) * scale;
                    d += double(((detail[q] - xv) - (zq - zv)).lengthSqr());
                }
            }
    return d;
}

// First half of the M-step: each boundary patch picks, among the continuations of the local patches it overlaps
// (and the zero field next to patches without detail), the Z whose gradient best matches X.
void chooseBoundaryZ(BoundaryPatches& bps, const VectorField& detail, const SeamProblem& problem)
{
    const PatchLayout& L = problem.layout;
    parallelFor(bps.patches.size(), 64, [&](size_t b, size_t e) {
        std::vector<std::pair<int, Coord>> cands; // (isZero, offset)
        for (size_t i = b; i < e; ++i) {
            BoundaryPatch& bp = bps.patches[i];
            const CoordBBox region = bps.region(bp);
            cands.clear();
            forEachOverlappedPatch(L, region, [&](size_t pi) {
                if (problem.active[pi]) cands.emplace_back(0, problem.offset[pi]);
                else cands.emplace_back(1, Coord(0));
            });
            std::sort(cands.begin(), cands.end(), [](const auto& x, const auto& y) {
                if (x.first != y.first) return x.first < y.first;
                return x.second < y.second;
            });
            cands.erase(std::unique(cands.begin(), cands.end()), cands.end());
            double best = -1.0;
            for (const auto& cand : cands) {
                const double d = gradientDistance(
                    detail, *problem.sourceHigh, problem.sourceScale, region, cand.first != 0, cand.second);
                if (best < 0.0 || d < best) {
                    best = d;
                    bp.zero = cand.first != 0;
                    bp.offset = cand.second;
                }
            }
        }
    });
}

// The target of X(q) - X(p) on the edge p -> q = p + e_a: the mean, over the boundary patches containing both
// ends, of Z's difference; an edge no boundary patch covers keeps the current field's difference. In blended
// patches it mixes with the advected detail's difference.
Vec3f edgeTarget(
    const BoundaryPatches& bps, const VectorField& detail, const SeamProblem& problem, const Coord& p, const Coord& q)
{
    const PatchLayout& L = problem.layout;
    const VectorField& Ush = *problem.sourceHigh;
    const float scale = problem.sourceScale;
    const int h = bps.h;
    // Centres c with p and q in [c - h, c + h - 1]: per axis k*h in [max(p,q) - h + 1, min(p,q) + h].
    int kLo[3], kHi[3];
    for (int s = 0; s < 3; ++s) {
        if (s == 2 && L.flat) {
            kLo[s] = kHi[s] = 0;
            continue;
        }
        const int lo = std::max(p[s], q[s]) - h + 1 - L.origin[s];
        const int hi = std::min(p[s], q[s]) + h - L.origin[s];
        kLo[s] = std::max(0, -floorDiv(-lo, h)); // ceil(lo / h)
        kHi[s] = std::min(bps.kCount[s] - 1, floorDiv(hi, h));
    }
    // Tent weights centred on each boundary patch: a cross-fade between overlapping patches instead of a
    // flat average, which would halve the energy where two different textures meet.
    Vec3f sum(0.0f);
    float wsum = 0.0f;
    const Vec3d mid = (p.asVec3d() + q.asVec3d()) * 0.5;
    for (int kx = kLo[0]; kx <= kHi[0]; ++kx)
        for (int ky = kLo[1]; ky <= kHi[1]; ++ky)
            for (int kz = kLo[2]; kz <= kHi[2]; ++kz) {
                const int id = bps.patchId[bps.kIndex(Coord(kx, ky, kz))];
                if (id < 0) continue;
                const BoundaryPatch& bp = bps.patches[size_t(id)];
                float wgt = 1.0f;
                for (int t = 0; t < (L.flat ? 2 : 3); ++t)
                    wgt *= std::max(0.0f, 1.0f - float(std::abs(mid[t] - (bp.centre[t] - 0.5))) / (0.6f * float(h)));
                if (wgt <= 0.0f) continue;
                if (!bp.zero) sum += (sourceAt(Ush, q + bp.offset) - sourceAt(Ush, p + bp.offset)) * (scale * wgt);
                wsum += wgt;
            }
    Vec3f t = wsum > 0.0f ? sum / wsum : detail[q] - detail[p];
    if (problem.temporal) {
        const float w = 0.5f * (problem.temporalWeights[L.patchIndex(L.patchOf(p))] +
                                   problem.temporalWeights[L.patchIndex(L.patchOf(q))]);
        const VectorField& T = *problem.temporal;
        if (w > 0.0f) t = t * (1.0f - w) + (T[q] - T[p]) * w;
    }
    return t;
}

// Second half of the M-step: the edge targets g of every edge row, from the boundary patches' chosen Z.
void setEdgeTargets(SeamSystem& sys, const BoundaryPatches& bps, const VectorField& detail, const SeamProblem& problem)
{
    const CoordBBox& box = detail.bbox();
    auto& targets = sys.targets();
    parallelFor(sys.rows(), 2048, [&](size_t b, size_t e) {
        for (size_t r = b; r < e; ++r) {
            const Coord p = detail.coordOf(sys.linear(r));
            for (int a = 0; a < 3; ++a) {
                Coord q = p;
                q[a] += 1;
                if (!box.isInside(q)) continue;
                targets[r * 3 + size_t(a)] = edgeTarget(bps, detail, problem, p, q);
            }
        }
    });
}

// The E-step with the solver and the tolerance (3D or 2D) the settings name.
SeamIteration solveEStep(SeamSystem& sys, VectorField& X, const SeamSettings& settings, bool flat)
{
    const double tolerance = flat ? settings.cgTolerance2D : settings.cgTolerance;
    if (settings.solver == SeamSolver::EigenLscg) return sys.solveLeastSquares(X, settings.maxCgIterations, tolerance);
    return sys.solve(X, settings.maxCgIterations, tolerance);
}

// The EM loop of section 3.3: M-step (boundary patches' Z, edge targets), then E-step, until E_b changes by
// less than emTolerance. A later M-step that moves E_b of the current X by no more than emTolerance leaves the next
// E-step where the last one ended (its CG already met the tolerance on nearly the same targets): EM stops there.
// On the heavy Blender pair's frames 5-30 that second E-step changed E_b by 0.01-0.9% and took 55% of the seams' time.
void runSeamEm(SeamSystem& sys, BoundaryPatches& bps, VectorField& detail, const SeamProblem& problem,
    const SeamSettings& settings, Progress* progress, SeamStats& stats)
{
    using Clock = std::chrono::steady_clock;
    const auto seconds = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
    double previous = -1.0;
    for (int it = 0; it < std::max(1, settings.maxEmIterations); ++it) {
        checkCancelled(progress);
        auto t0 = Clock::now();
        chooseBoundaryZ(bps, detail, problem);
        setEdgeTargets(sys, bps, detail, problem);
        if (it == 0) stats.initialEnergy = sys.energy(detail);
        if (previous > 0.0) {
            const double moved = sys.energy(detail);
            if (std::abs(previous - moved) <= settings.emTolerance * previous) {
                stats.mStepSeconds += seconds(t0);
                stats.stoppedAtMStep = moved;
                stats.converged = true;
                break;
            }
        }
        stats.mStepSeconds += seconds(t0);
        t0 = Clock::now();
        SeamIteration s = solveEStep(sys, detail, settings, problem.layout.flat);
        stats.eStepSeconds += seconds(t0);
        stats.iterations.push_back(s);
        if (progress) progress->update(double(it + 1) / std::max(1, settings.maxEmIterations));
        if (previous > 0.0 && std::abs(previous - s.energy) <= settings.emTolerance * previous) {
            stats.converged = true;
            break;
        }
        previous = s.energy;
    }
}

} // namespace

SeamStats smoothSeams(VectorField& detail, const SeamProblem& problem, const SeamSettings& settings, Progress* progress)
{
    SeamStats stats;
    if (!settings.enabled) return stats;
    const int C = boundaryPatchEdge(problem, settings);
    const PatchLayout& L = problem.layout;

    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    const std::vector<uint8_t> omega = seamUnknowns(detail, problem, settings);
    if (problem.temporal && problem.temporalWeights.size() != L.patchCount())
        throw ValueError("smoothSeams: temporalWeights must hold one weight per local patch");
    if (problem.base && problem.base->bbox() != detail.bbox())
        throw ValueError("smoothSeams: the base field must cover the detail field's box");
    SeamSystem sys(detail, omega, settings.gamma, problem.base, problem.baseScale);
    if (problem.boxFactor > 1 && settings.boxWeight > 0.0f)
        sys.enableBoxRows(detail, problem.boxFactor, settings.boxWeight, settings.boxKeep);
    if (settings.valueWeight > 0.0f && problem.temporal && !problem.temporalWeights.empty())
        sys.enableValueRows(detail,
            [&](const Coord& c) { return settings.valueWeight * problem.temporalWeights[L.patchIndex(L.patchOf(c))]; });
    stats.bandVoxels = sys.unknowns();
    if (stats.bandVoxels == 0) {
        stats.converged = true;
        return stats;
    }
    BoundaryPatches bps = placeBoundaryPatches(L, problem.active, C);
    stats.boundaryPatches = bps.patches.size();
    stats.setupSeconds = std::chrono::duration<double>(Clock::now() - t0).count();
    runSeamEm(sys, bps, detail, problem, settings, progress, stats);
    return stats;
}

} // namespace turb
