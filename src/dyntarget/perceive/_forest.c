/* dyntarget's random-forest kernel: predict_proba of a packed scikit-learn forest.
 *
 * Built at run time by dyntarget.perceive.compiled (cc -O2 -march=native), which also
 * packs the forest; the layout is described there. In short, per tree, nodes are in
 * breadth-first order with the two children of a node next to each other, so
 *
 *     next = child(k) + (x[feature(k)] > threshold(k))
 *
 * where code[k] = child << fshift | feature and threshold[k] is the float64 threshold
 * rounded down to float32 (x <= t in float64 iff x <= that float32, x being float32).
 * A leaf points to itself with threshold +inf, so walking past it changes nothing.
 * value[k] is the leaf's plume fraction (tree_.value[k, 0, 1]); each pixel's fractions
 * are summed in float64 in tree order and divided by the number of trees, exactly as
 * scikit-learn's ForestClassifier.predict_proba does, so the result is bit-identical.
 *
 * With AVX-512, 16 pixels move down a tree at once. The first TOP levels read the
 * tree's first 32 nodes from registers (breadth-first, the nodes of depth <= 4 are
 * among them); deeper levels load each lane's node with scalar loads (on the CPUs
 * measured, faster than the gather instruction), and a group of 16 pixels stops as
 * soon as all of them sit on leaves (half the pixels of a typical scene do by depth 6).
 * Without AVX-512 the same level-by-level walk runs in plain C (the compiler may
 * vectorise it).
 */
#include <stdint.h>
#include <string.h>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif

#define BLOCK 1024 /* pixels per block: their features, nodes and sums stay in cache */
#define MAXF 8     /* features per pixel at most */
#define TOP 5      /* levels read from the 32-node register table */

int dt_forest_abi(void) { return 1; }

int dt_forest_avx512(void)
{
#if defined(__AVX512F__)
    return 1;
#else
    return 0;
#endif
}

#if defined(__AVX512F__)
/* One level for 16 pixels: their nodes' thresholds and codes in, their next nodes out. */
static inline __m512i step(__m512 th, __m512i c, float xs[][BLOCK], int g, int nfeat,
                           int fshift)
{
    const __m512i f = _mm512_and_si512(c, _mm512_set1_epi32((1 << fshift) - 1));
    __m512 v = _mm512_load_ps(xs[0] + g);
    for (int j = 1; j < nfeat; j++)
        v = _mm512_mask_mov_ps(v, _mm512_cmpeq_epi32_mask(f, _mm512_set1_epi32(j)),
                               _mm512_load_ps(xs[j] + g));
    const __mmask16 right = _mm512_cmp_ps_mask(v, th, _CMP_GT_OQ);
    const __m512i next = _mm512_srai_epi32(c, fshift);
    return _mm512_mask_add_epi32(next, right, next, _mm512_set1_epi32(1));
}

/* One tree for a block: idx holds the root, and the leaves on return. */
static void walk(float xs[][BLOCK], int32_t *idx, int32_t root, int nfeat, int fshift,
                 int depth, const int64_t *node, const float *thr, const int32_t *code)
{
    const __m512i base = _mm512_set1_epi32(root);
    const __m512 t0 = _mm512_loadu_ps(thr + root), t1 = _mm512_loadu_ps(thr + root + 16);
    const __m512i c0 = _mm512_loadu_si512(code + root), c1 = _mm512_loadu_si512(code + root + 16);
    const int top = depth < TOP ? depth : TOP;
    for (int d = 0; d < top; d++) /* breadth-first, the nodes of depth < TOP are the first 31 */
        for (int g = 0; g < BLOCK; g += 16) {
            const __m512i rel = _mm512_sub_epi32(_mm512_load_si512(idx + g), base);
            _mm512_store_si512(idx + g, step(_mm512_permutex2var_ps(t0, rel, t1),
                                             _mm512_permutex2var_epi32(c0, rel, c1), xs, g,
                                             nfeat, fshift));
        }
    const __m512i even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26,
                                           28, 30);
    const __m512i odd = _mm512_add_epi32(even, _mm512_set1_epi32(1));
    int active[BLOCK / 16], na = BLOCK / 16;
    for (int q = 0; q < na; q++) active[q] = 16 * q;
    for (int d = top; d < depth && na > 0; d++) {
        int keep = 0;
        for (int a = 0; a < na; a++) {
            const int g = active[a];
            int64_t w[16] __attribute__((aligned(64)));
            for (int i = 0; i < 16; i++) w[i] = node[idx[g + i]]; /* scalar loads */
            const __m512i lo = _mm512_load_si512(w), hi = _mm512_load_si512(w + 8);
            const __m512i k = _mm512_load_si512(idx + g);
            const __m512i next = step(_mm512_castsi512_ps(_mm512_permutex2var_epi32(lo, even, hi)),
                                      _mm512_permutex2var_epi32(lo, odd, hi), xs, g, nfeat,
                                      fshift);
            _mm512_store_si512(idx + g, next);
            if (_mm512_cmpneq_epi32_mask(next, k)) active[keep++] = g; /* not all on leaves */
        }
        na = keep;
    }
}
#else
static void walk(float xs[][BLOCK], int32_t *idx, int32_t root, int nfeat, int fshift,
                 int depth, const int64_t *node, const float *thr, const int32_t *code)
{
    (void)root, (void)nfeat, (void)node;
    const int32_t fmask = (1 << fshift) - 1;
    int active[BLOCK / 16], na = BLOCK / 16;
    for (int q = 0; q < na; q++) active[q] = 16 * q;
    for (int d = 0; d < depth && na > 0; d++) {
        int keep = 0;
        for (int a = 0; a < na; a++) {
            const int g = active[a];
            int moved = 0;
            for (int i = g; i < g + 16; i++) {
                const int32_t k = idx[i], c = code[k];
                const int32_t next = (c >> fshift) + (xs[c & fmask][i] > thr[k]);
                moved |= next != k;
                idx[i] = next;
            }
            if (moved) active[keep++] = g;
        }
        na = keep;
    }
}
#endif

int dt_forest_predict(const float *x, int64_t n, int32_t nfeat, int32_t fshift, int32_t depth,
                      const int64_t *node, const float *thr, const int32_t *code,
                      const double *value, const int32_t *roots, int32_t ntrees, double *out)
{
    if (nfeat < 1 || nfeat > MAXF || fshift < 0 || fshift > 3 || depth < 0 || ntrees < 1)
        return -1;
    float xs[MAXF][BLOCK] __attribute__((aligned(64)));
    int32_t idx[BLOCK] __attribute__((aligned(64)));
    double acc[BLOCK] __attribute__((aligned(64)));
    for (int64_t b = 0; b < n; b += BLOCK) {
        const int m = (n - b < BLOCK) ? (int)(n - b) : BLOCK;
        memset(xs, 0, sizeof xs); /* lanes past m walk valid paths and are not written */
        for (int i = 0; i < m; i++)
            for (int j = 0; j < nfeat; j++) xs[j][i] = x[(b + i) * nfeat + j];
        for (int i = 0; i < BLOCK; i++) acc[i] = 0.0;
        for (int t = 0; t < ntrees; t++) {
            for (int i = 0; i < BLOCK; i++) idx[i] = roots[t];
            walk(xs, idx, roots[t], nfeat, fshift, depth, node, thr, code);
            for (int i = 0; i < BLOCK; i++) acc[i] += value[idx[i]]; /* in tree order */
        }
        for (int i = 0; i < m; i++) out[b + i] = acc[i] / ntrees;
    }
    return 0;
}
