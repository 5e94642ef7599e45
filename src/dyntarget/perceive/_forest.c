/* dyntarget's random-forest kernel: predict_proba of a packed scikit-learn forest.
 *
 * Built ahead of time by 'dyntarget export-onnx --targets x86-64-v3,x86-64-v4,aarch64'
 * into the model directory (dyntarget.perceive.compiled.build_kernels; bound to its
 * forest.npz by SHA-256 in forest.json), or at run time with the C compiler on the PATH
 * and cached; the forest is packed by dyntarget.perceive.compiled, where the layout is
 * described. In short, per
 * tree, nodes are in breadth-first order with the two children of a node next to each
 * other, so
 *
 *     next = child(k) + (x[feature(k)] > threshold(k))
 *
 * where code[k] = child << fshift | feature and threshold[k] is the float64 threshold
 * rounded down to float32 (x <= t in float64 iff x <= that float32, x being float32).
 * A leaf points to itself with threshold +inf, so walking past it changes nothing.
 * value[k] is the leaf's plume fraction (tree_.value[k, 0, 1]); each pixel's fractions
 * are summed in float64 in tree order and divided by the number of trees, exactly as
 * scikit-learn's ForestClassifier.predict_proba does, so the result is bit-identical on
 * every path.
 *
 * One source, one path per instruction set, chosen by the compiler's target macros:
 *
 *   avx512   (-march=x86-64-v4)  16 pixels per step; the first 5 levels from a 32-node
 *                                register table (vpermt2ps), deeper levels scalar loads;
 *   avx2     (-march=x86-64-v3)  8 pixels per step; the first 4 levels from a 16-node
 *                                register table (two vpermps and a blend);
 *   neon     (aarch64) / sse2 (x86-64 baseline): 4 pixels per step with GCC vector
 *                                extensions (the same C for both), scalar node loads;
 *   portable (-DDT_FOREST_SCALAR) plain C, one pixel at a time.
 *
 * Every path moves a group of pixels one level at a time and stops the group as soon as
 * all its pixels sit on leaves (half the pixels of a typical scene do by depth 6).
 */
#include <stdint.h>
#include <string.h>
#if !defined(DT_FOREST_SCALAR) && (defined(__AVX512F__) || defined(__AVX2__))
#include <immintrin.h>
#endif

#define BLOCK 1024 /* pixels per block: their features, nodes and sums stay in cache */
#define MAXF 8     /* features per pixel at most */

#if defined(DT_FOREST_SCALAR)
#define DT_ISA 0
#elif defined(__AVX512F__)
#define DT_ISA 4
#elif defined(__AVX2__)
#define DT_ISA 3
#elif defined(__ARM_NEON) || defined(__aarch64__)
#define DT_ISA 2
#elif defined(__SSE2__)
#define DT_ISA 1
#else
#define DT_ISA 0
#endif

/* 2: the ABI of dt_forest_predict below (1 had dt_forest_avx512 instead of dt_forest_isa) */
int dt_forest_abi(void) { return 2; }

/* 0 portable, 1 sse2, 2 neon, 3 avx2, 4 avx512: the path this build runs */
int dt_forest_isa(void) { return DT_ISA; }

#if DT_ISA == 4
#define TOP 5 /* levels read from the 32-node register table */
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
            const int32_t *at = idx + g; /* scalar loads straight into registers */
            const __m512i lo = _mm512_set_epi64(node[at[7]], node[at[6]], node[at[5]], node[at[4]],
                                                node[at[3]], node[at[2]], node[at[1]], node[at[0]]);
            const __m512i hi = _mm512_set_epi64(node[at[15]], node[at[14]], node[at[13]],
                                                node[at[12]], node[at[11]], node[at[10]],
                                                node[at[9]], node[at[8]]);
            const __m512i k = _mm512_load_si512(at);
            const __m512i next = step(_mm512_castsi512_ps(_mm512_permutex2var_epi32(lo, even, hi)),
                                      _mm512_permutex2var_epi32(lo, odd, hi), xs, g, nfeat,
                                      fshift);
            _mm512_store_si512(idx + g, next);
            active[keep] = g; /* kept (no branch to mispredict) unless all sit on leaves */
            keep += _mm512_cmpneq_epi32_mask(next, k) != 0;
        }
        na = keep;
    }
}
#elif DT_ISA == 3
#define TOP 4 /* levels read from the 16-node register table */
/* One level for 8 pixels: their nodes' thresholds and codes in, their next nodes out. */
static inline __m256i step(__m256 th, __m256i c, float xs[][BLOCK], int g, int nfeat,
                           int fshift)
{
    const __m256i f = _mm256_and_si256(c, _mm256_set1_epi32((1 << fshift) - 1));
    __m256 v = _mm256_load_ps(xs[0] + g);
    for (int j = 1; j < nfeat; j++)
        v = _mm256_blendv_ps(v, _mm256_load_ps(xs[j] + g),
                             _mm256_castsi256_ps(_mm256_cmpeq_epi32(f, _mm256_set1_epi32(j))));
    const __m256i right = _mm256_castps_si256(_mm256_cmp_ps(v, th, _CMP_GT_OQ)); /* -1 or 0 */
    return _mm256_sub_epi32(_mm256_srai_epi32(c, fshift), right);
}

static void walk(float xs[][BLOCK], int32_t *idx, int32_t root, int nfeat, int fshift,
                 int depth, const int64_t *node, const float *thr, const int32_t *code)
{
    const __m256i base = _mm256_set1_epi32(root), seven = _mm256_set1_epi32(7);
    const __m256 t0 = _mm256_loadu_ps(thr + root), t1 = _mm256_loadu_ps(thr + root + 8);
    const __m256i c0 = _mm256_loadu_si256((const __m256i *)(code + root));
    const __m256i c1 = _mm256_loadu_si256((const __m256i *)(code + root + 8));
    const int top = depth < TOP ? depth : TOP;
    for (int d = 0; d < top; d++) /* breadth-first, the nodes of depth < TOP are the first 15 */
        for (int g = 0; g < BLOCK; g += 8) {
            const __m256i rel = _mm256_sub_epi32(_mm256_load_si256((const __m256i *)(idx + g)), base);
            const __m256i high = _mm256_cmpgt_epi32(rel, seven);
            const __m256 th = _mm256_blendv_ps(_mm256_permutevar8x32_ps(t0, rel),
                                               _mm256_permutevar8x32_ps(t1, rel),
                                               _mm256_castsi256_ps(high));
            const __m256i c = _mm256_blendv_epi8(_mm256_permutevar8x32_epi32(c0, rel),
                                                 _mm256_permutevar8x32_epi32(c1, rel), high);
            _mm256_store_si256((__m256i *)(idx + g), step(th, c, xs, g, nfeat, fshift));
        }
    const __m256i split = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    int active[BLOCK / 8], na = BLOCK / 8;
    for (int q = 0; q < na; q++) active[q] = 8 * q;
    for (int d = top; d < depth && na > 0; d++) {
        int keep = 0;
        for (int a = 0; a < na; a++) {
            const int g = active[a];
            const int32_t *at = idx + g;
            /* scalar loads put straight into registers (through a buffer, the vector load
               would wait for the eight stores to retire: a store-forwarding stall) */
            const __m256i w0 = _mm256_set_epi64x(node[at[3]], node[at[2]], node[at[1]], node[at[0]]);
            const __m256i w1 = _mm256_set_epi64x(node[at[7]], node[at[6]], node[at[5]], node[at[4]]);
            /* (t0 c0 t1 c1 ...) -> (t0 t1 t2 t3 c0 c1 c2 c3) per half, then the halves joined */
            const __m256i lo = _mm256_permutevar8x32_epi32(w0, split);
            const __m256i hi = _mm256_permutevar8x32_epi32(w1, split);
            const __m256i th = _mm256_permute2x128_si256(lo, hi, 0x20);
            const __m256i c = _mm256_permute2x128_si256(lo, hi, 0x31);
            const __m256i k = _mm256_load_si256((const __m256i *)at);
            const __m256i next = step(_mm256_castsi256_ps(th), c, xs, g, nfeat, fshift);
            _mm256_store_si256((__m256i *)(idx + g), next);
            active[keep] = g; /* kept (no branch to mispredict) unless all sit on leaves */
            keep += _mm256_movemask_epi8(_mm256_cmpeq_epi32(next, k)) != -1;
        }
        na = keep;
    }
}
#elif DT_ISA == 1 || DT_ISA == 2
/* GCC / Clang vector extensions: NEON on aarch64, SSE2 on x86-64, the same C. */
typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));
typedef int64_t vl2 __attribute__((vector_size(16)));
#if defined(__clang__)
#define SHUFFLE(a, b, i, j, k, l) __builtin_shufflevector(a, b, i, j, k, l)
#else
#define SHUFFLE(a, b, i, j, k, l) __builtin_shuffle(a, b, (vi4){i, j, k, l})
#endif

static void walk(float xs[][BLOCK], int32_t *idx, int32_t root, int nfeat, int fshift,
                 int depth, const int64_t *node, const float *thr, const int32_t *code)
{
    (void)root, (void)thr, (void)code;
    const vi4 fmask = {(1 << fshift) - 1, (1 << fshift) - 1, (1 << fshift) - 1, (1 << fshift) - 1};
    int active[BLOCK / 4], na = BLOCK / 4;
    for (int q = 0; q < na; q++) active[q] = 4 * q;
    for (int d = 0; d < depth && na > 0; d++) {
        int keep = 0;
        for (int a = 0; a < na; a++) {
            const int g = active[a];
            const int32_t *at = idx + g;
            vi4 k;
            memcpy(&k, at, sizeof k);
            /* scalar loads of each lane's node straight into registers: (t0 c0 t1 c1) and
               (t2 c2 t3 c3) (little-endian), split into thresholds and codes */
            const vl2 w0 = {node[at[0]], node[at[1]]}, w1 = {node[at[2]], node[at[3]]};
            const vi4 tb = SHUFFLE((vi4)w0, (vi4)w1, 0, 2, 4, 6);
            const vi4 c = SHUFFLE((vi4)w0, (vi4)w1, 1, 3, 5, 7);
            const vi4 f = c & fmask;
            vf4 v;
            memcpy(&v, xs[0] + g, sizeof v);
            for (int j = 1; j < nfeat; j++) {
                vf4 xj;
                memcpy(&xj, xs[j] + g, sizeof xj);
                const vi4 m = f == (vi4){j, j, j, j};
                v = (vf4)(((vi4)v & ~m) | ((vi4)xj & m));
            }
            vf4 th;
            memcpy(&th, &tb, sizeof th);
            const vi4 next = (c >> fshift) - (vi4)(v > th); /* a true lane compares as -1 */
            memcpy(idx + g, &next, sizeof next);
            const vi4 moved = next != k;
            active[keep] = g; /* kept (no branch to mispredict) unless all sit on leaves */
            keep += (moved[0] | moved[1] | moved[2] | moved[3]) != 0;
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
            active[keep] = g; /* kept (no branch to mispredict) unless all sit on leaves */
            keep += moved;
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
