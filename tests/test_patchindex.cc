// PCA + FLANN adaptor: exactness on analytic sets and agreement with brute force.
#include "TestUtil.h"

#include <turb/Parallel.h>
#include <turb/PatchIndex.h>

#include <random>

using namespace turb;

TEST(Pca, ReconstructsARankKSetExactly)
{
    // 500 rows in 40 dimensions spanned by 5 random directions plus an offset.
    const size_t n = 500, dim = 40, rank = 5;
    std::mt19937 rng(7);
    std::normal_distribution<float> g(0.0f, 1.0f);
    std::vector<float> dirs(rank * dim), offset(dim), rows(n * dim);
    for (auto& v : dirs) v = g(rng);
    for (auto& v : offset) v = 3.0f * g(rng);
    for (size_t i = 0; i < n; ++i) {
        float c[rank];
        for (auto& v : c) v = g(rng);
        for (size_t d = 0; d < dim; ++d) {
            float v = offset[d];
            for (size_t r = 0; r < rank; ++r) v += c[r] * dirs[r * dim + d];
            rows[i * dim + d] = v;
        }
    }
    Pca pca;
    pca.fit(rows.data(), n, dim, PcaSettings{int(rank)});
    EXPECT_EQ(pca.outputDim(), rank);
    EXPECT_NEAR(pca.explainedVariance(), 1.0, 1e-6);
    std::vector<float> coeff(rank), back(dim);
    double maxErr = 0.0;
    for (size_t i = 0; i < n; ++i) {
        pca.project(&rows[i * dim], coeff.data());
        pca.reconstruct(coeff.data(), back.data());
        for (size_t d = 0; d < dim; ++d) maxErr = std::max(maxErr, double(std::abs(back[d] - rows[i * dim + d])));
    }
    EXPECT_LT(maxErr, 1e-3);

    // Fewer axes than the rank lose variance.
    Pca small;
    small.fit(rows.data(), n, dim, PcaSettings{2});
    EXPECT_LT(small.explainedVariance(), 0.95);
}

TEST(PatchIndex, AgreesWithBruteForce)
{
    const size_t n = 2000, dim = 12;
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<float> rows(n * dim), queries(100 * dim);
    for (auto& v : rows) v = u(rng);
    for (auto& v : queries) v = u(rng);
    PatchIndex index;
    index.build(rows, dim, PcaSettings{int(dim)}); // full rank: distances are exact
    ASSERT_EQ(index.size(), n);
    std::vector<int> idx;
    std::vector<float> d2;
    index.queryMany(queries.data(), 100, 3, idx, d2);
    for (size_t q = 0; q < 100; ++q) {
        std::vector<std::pair<float, int>> all;
        for (size_t i = 0; i < n; ++i) {
            float s = 0;
            for (size_t d = 0; d < dim; ++d) {
                const float e = rows[i * dim + d] - queries[q * dim + d];
                s += e * e;
            }
            all.emplace_back(s, int(i));
        }
        std::partial_sort(all.begin(), all.begin() + 3, all.end());
        for (int j = 0; j < 3; ++j) {
            EXPECT_EQ(idx[q * 3 + size_t(j)], all[size_t(j)].second) << "query " << q << " rank " << j;
            EXPECT_NEAR(d2[q * 3 + size_t(j)], all[size_t(j)].first, 1e-4f);
        }
    }
}

TEST(PatchIndex, QueriesAreIdenticalAtAnyThreadCount)
{
    const size_t n = 3000, dim = 30;
    std::mt19937 rng(3);
    std::normal_distribution<float> g;
    std::vector<float> rows(n * dim), queries(500 * dim);
    for (auto& v : rows) v = g(rng);
    for (auto& v : queries) v = g(rng);
    std::vector<int> i1, i2;
    std::vector<float> d1, d2;
    withThreads(1, [&] {
        PatchIndex index;
        index.build(rows, dim, PcaSettings{8});
        index.queryMany(queries.data(), 500, 2, i1, d1);
    });
    withThreads(2, [&] {
        PatchIndex index;
        index.build(rows, dim, PcaSettings{8});
        index.queryMany(queries.data(), 500, 2, i2, d2);
    });
    EXPECT_EQ(i1, i2);
    EXPECT_EQ(d1, d2);
}
