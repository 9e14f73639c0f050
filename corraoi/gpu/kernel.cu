// corraoi's GPU kernels: one CUDA thread per run, every built-in policy family.
//
// CuPy compiles this file with NVRTC (corraoi/gpu/device.py); the same text also compiles as
// plain C++ (the emulated device: a loop over runs instead of a thread grid), so that the
// policy logic is tested on machines without a GPU. Compile-time constants: KARMS (arms) and,
// optionally, CAI_FAMILY (compile one family's entry points only: its index in FAMILIES of
// device.py, plus one; 0 or unset: all), CAI_CAPTURE (1: the module that captures one run's
// slots for `record --from`, with the policy's scores; 0, default: a sweep's, compiled from
// the same text as before the capture of scores existed, see CAI_CAPW), and two switches
// that benchmarks/bench_gpu.py times
// against the default: CAI_FP64 (1: the arithmetic in double precision; default 0, single)
// and CAI_LOG_TEST (how the gamma trials' log tests run: 0, default, for every trial; 1, only
// where the squeeze leaves one undecided; 2, batched after the arms; see cai_betas).
//
// Per run, per slot (the CPU kernel corraoi/engine/_kernel.py does the same in the same order):
// draw the hidden state from the run's hidden stream, let the policy force an arm, restrict
// to the correlated candidate set (correlated forms), apply the AoI-aware override (aware
// forms), else play the argmax of the policy's score over the candidates (ties uniformly at
// random); then update counts, ages and the policy's state.
//
// Random numbers: Philox4x32-10 (Salmon, Moraes, Dror, Shaw 2011), keyed by the run's 64-bit
// seed; every 32-bit word is used. The counter (c0, c1, c2, c3) names what a block is for:
// (b, 0, HIDDEN, 0) holds the hidden uniforms of slots 4b + 1 .. 4b + 4, one word each;
// (b, 0, EXPLORE, 0) the exploration coin and arm of slots 2b + 1 and 2b + 2 (Q-UCB, Q-TS);
// (t, 0, POLICY, q) the q-th block the policy draws in slot t (q = 0, 1, ... in order of
// use: posterior samples, redrawn gamma trials, tie-breaks). So every number is a function of
// (seed, slot, purpose, index) alone: nothing is carried between launches and nothing depends
// on the launch shape, and every policy sees the same hidden path for a seed. Sums are 64-bit
// (AoI sums pass 2^31 near T = 1.3e9); pulls and successes of an arm, at most T < 2^32, are
// 32-bit in registers and 64-bit in memory.
//
// Written for the GPU's habits (docs/gpu.md, "How the kernel is written"): single-precision
// arithmetic with the fast hardware functions for the samplers (Hopper's double-precision
// logarithms and roots are long instruction sequences), a run's per-arm values in registers
// (every loop over the arms is unrolled and an arm chosen at run time is read and written
// through comparisons, never an index), sets of arms as bit masks, what changes only when an
// arm is played recomputed for that arm alone, ln t from a per-launch table (every run of a
// launch is at the same slot), the hidden state by integer comparisons with the CDF scaled to
// 2^32, and the sampling families drawing in whole Philox blocks so that the threads of a
// warp stay in step.

#if defined(__CUDACC__)
#define CAI_FN __device__ __forceinline__
#define CAI_METHOD __device__ __forceinline__
#define CAI_STATIC static __device__ __forceinline__
#else
#include <math.h>
#include <string.h>
#define CAI_FN static inline
#define CAI_METHOD inline
#define CAI_STATIC static inline
#endif

typedef unsigned int u32;
typedef unsigned long long u64;
typedef long long i64;

#ifndef KARMS
#error "compile with -DKARMS=<number of arms>"
#endif
#if KARMS < 1 || KARMS > 64
#error "KARMS must be 1..64 (sets of arms are 64-bit masks)"
#endif
#ifndef CAI_FAMILY
#define CAI_FAMILY 0
#endif
#define CAI_WANT(id) (CAI_FAMILY == 0 || CAI_FAMILY == (id))
#ifndef CAI_FP64
#define CAI_FP64 0
#endif
#ifndef CAI_LOG_TEST
#define CAI_LOG_TEST 0
#endif
#ifndef CAI_CAPTURE
#define CAI_CAPTURE 0
#endif

// Per-arm arrays stay in registers only while each index is a compile-time constant: on the
// GPU, up to 16 arms, loops over the arms are unrolled and cai_get/cai_set compare instead of
// indexing. Beyond (and on the host) they are plain arrays.
#if defined(__CUDACC__) && KARMS <= 16
#define CAI_REGS 1
#define CAI_FOR_ARMS(k) _Pragma("unroll") for (int k = 0; k < KARMS; ++k)
#else
#define CAI_REGS 0
#define CAI_FOR_ARMS(k) for (int k = 0; k < KARMS; ++k)
#endif

// A set of arms: 32 bits where that is enough (fewer instructions), else 64.
#if KARMS <= 32
typedef u32 cai_mask;
#else
typedef u64 cai_mask;
#endif
#define CAI_ALL_ARMS ((cai_mask)(~0ull >> (64 - KARMS)))
#define CAI_BIT(k) ((cai_mask)1 << (k))
#define CAI_HAS(mask, k) ((((mask) >> (k)) & (cai_mask)1) != (cai_mask)0)

#define CAI_PURPOSE_HIDDEN 0x48494444u
#define CAI_PURPOSE_POLICY 0x504f4c49u
#define CAI_PURPOSE_EXPLORE 0x4558504cu

template <class T>
CAI_FN T cai_get(const T* a, int i) {
#if CAI_REGS  // selects, never a[i]: the compiler would turn `if (k == i) a[k]` into a[i]
    T v = a[0];
    CAI_FOR_ARMS(k) v = k == i ? a[k] : v;
    return v;
#else
    return a[i];
#endif
}

template <class T>
CAI_FN void cai_set(T* a, int i, const T& v) {
#if CAI_REGS
    CAI_FOR_ARMS(k) a[k] = k == i ? v : a[k];
#else
    a[i] = v;
#endif
}

// ------------------------------------------------------------------ arithmetic
//
// `real` is the precision of the policies' arithmetic: float (default) or double (CAI_FP64).
// The samplers use the GPU's hardware approximations in single precision (logarithm, roots,
// sine, cosine, division: one instruction each, against tens for their double forms); means
// are correctly rounded quotients s / n, so that arms with equal ratios tie exactly, as on
// the CPU.

#if CAI_FP64
typedef double real;
#else
typedef float real;
#endif

CAI_FN real cai_inf() {
#if defined(__CUDACC__)
#if CAI_FP64
    return __longlong_as_double(0x7ff0000000000000LL);
#else
    return __int_as_float(0x7f800000);
#endif
#else
    return (real)HUGE_VAL;
#endif
}

CAI_FN real cai_max(real a, real b) {  // neither is NaN
#if defined(__CUDACC__)
    return fmax(a, b);  // one instruction (FMNMX) in single precision
#else
    return a > b ? a : b;
#endif
}

// The device's single-precision functions are its hardware approximations (one instruction
// each: MUFU.LG2, .SQRT, .RSQ, .SIN, .COS, .RCP), written as PTX so that no range check or
// slow path comes with them: their arguments here are positive normal numbers (or, for sin
// and cos, within [-pi, pi]).
#if defined(__CUDACC__) && !CAI_FP64
#define CAI_PTX1(NAME, OP)                                                                    \
    CAI_FN float NAME(float x) {                                                              \
        float y;                                                                              \
        asm(OP " %0, %1;" : "=f"(y) : "f"(x));                                                \
        return y;                                                                             \
    }
CAI_PTX1(cai_lg2_approx, "lg2.approx.ftz.f32")
CAI_PTX1(cai_sqrt_approx, "sqrt.approx.ftz.f32")
CAI_PTX1(cai_rsqrt_approx, "rsqrt.approx.ftz.f32")
CAI_PTX1(cai_sin_approx, "sin.approx.ftz.f32")
CAI_PTX1(cai_cos_approx, "cos.approx.ftz.f32")
CAI_FN float cai_div_approx(float a, float b) {
    float y;
    asm("div.approx.ftz.f32 %0, %1, %2;" : "=f"(y) : "f"(a), "f"(b));
    return y;
}
#endif

CAI_FN real cai_log2(real x) {  // x > 0
#if defined(__CUDACC__) && !CAI_FP64
    return cai_lg2_approx(x);
#else
    return log2(x);
#endif
}

CAI_FN real cai_log(real x) { return cai_log2(x) * (real)0.69314718055994530942; }

CAI_FN real cai_sqrt(real x) {  // x >= 0
#if defined(__CUDACC__) && !CAI_FP64
    return cai_sqrt_approx(x);
#else
    return sqrt(x);
#endif
}

CAI_FN real cai_rsqrt(real x) {  // x >= 0
#if defined(__CUDACC__) && !CAI_FP64
    return cai_rsqrt_approx(x);
#elif defined(__CUDACC__)
    return rsqrt(x);
#else
    return (real)1 / sqrt(x);
#endif
}

// a / b where a few units in the last place do not matter (a sample, not a mean).
CAI_FN real cai_qdiv(real a, real b) {
#if defined(__CUDACC__) && !CAI_FP64
    return cai_div_approx(a, b);
#else
    return a / b;
#endif
}

// sin and cos of 2 pi u - pi, u in [0, 1).
CAI_FN void cai_sincos_turn(real u, real* s, real* c) {
#if defined(__CUDACC__) && !CAI_FP64
    float a = 6.28318530717958647692f * u - 3.14159265358979323846f;
    *s = cai_sin_approx(a);
    *c = cai_cos_approx(a);
#elif defined(__CUDACC__)
    sincospi(2.0 * u - 1.0, s, c);
#else
    double a = 6.28318530717958647692 * (double)u - 3.14159265358979323846;
    *s = (real)sin(a);
    *c = (real)cos(a);
#endif
}

CAI_FN u32 cai_mulhi(u32 a, u32 b) {
#if defined(__CUDACC__)
    return __umulhi(a, b);
#else
    return (u32)(((u64)a * (u64)b) >> 32);
#endif
}

CAI_FN int cai_lowest(cai_mask mask) {  // the lowest set bit of a nonzero mask
#if defined(__CUDACC__)
#if KARMS <= 32
    return __ffs((int)mask) - 1;
#else
    return __ffsll((long long)mask) - 1;
#endif
#else
    return __builtin_ctzll((u64)mask);
#endif
}

CAI_FN int cai_popc(cai_mask mask) {
#if defined(__CUDACC__)
#if KARMS <= 32
    return __popc(mask);
#else
    return __popcll(mask);
#endif
#else
    return __builtin_popcountll((u64)mask);
#endif
}

CAI_FN i64 cai_bits_of(double v) {
#if defined(__CUDACC__)
    return __double_as_longlong(v);
#else
    i64 b;
    memcpy(&b, &v, sizeof b);
    return b;
#endif
}

CAI_FN double cai_double_of(i64 b) {
#if defined(__CUDACC__)
    return __longlong_as_double(b);
#else
    double v;
    memcpy(&v, &b, sizeof v);
    return v;
#endif
}

// ------------------------------------------------------------------ Philox4x32-10

struct CaiWords {
    u32 w0, w1, w2, w3;
};

CAI_FN CaiWords cai_philox(u32 c0, u32 c1, u32 c2, u32 c3, u32 k0, u32 k1) {
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int i = 0; i < 10; ++i) {
        if (i > 0) {
            k0 += 0x9E3779B9u;
            k1 += 0xBB67AE85u;
        }
        u32 hi0 = cai_mulhi(0xD2511F53u, c0);
        u32 lo0 = 0xD2511F53u * c0;
        u32 hi1 = cai_mulhi(0xCD9E8D57u, c2);
        u32 lo1 = 0xCD9E8D57u * c2;
        u32 n0 = hi1 ^ c1 ^ k0;
        u32 n2 = hi0 ^ c3 ^ k1;
        c0 = n0;
        c1 = lo1;
        c2 = n2;
        c3 = lo0;
    }
    CaiWords out = {c0, c1, c2, c3};
    return out;
}

// Uniforms from one word: [0, 1) and (0, 1]. Single precision: the word's top 23 bits as the
// mantissa of a float in [1, 2) (two integer instructions and a subtraction, no conversion);
// double: all 32 bits.
CAI_FN real cai_u01(u32 w) {
#if CAI_FP64
    return (double)w * 2.3283064365386963e-10;
#else
    u32 b = 0x3f800000u | (w >> 9);
    float f;
#if defined(__CUDACC__)
    f = __uint_as_float(b);
#else
    memcpy(&f, &b, sizeof f);
#endif
    return f - 1.0f;
#endif
}

CAI_FN real cai_u01_open(u32 w) {  // (0, 1]: a logarithm of it is finite; 1 - cai_u01(w)
#if CAI_FP64
    return ((double)w + 1.0) * 2.3283064365386963e-10;
#else
    u32 b = 0x3f800000u | (w >> 9);
    float f;
#if defined(__CUDACC__)
    f = __uint_as_float(b);
#else
    memcpy(&f, &b, sizeof f);
#endif
    return 2.0f - f;  // exact
#endif
}

// The draws of a run in one slot: block q of (t, POLICY) for q = 0, 1, ... in order of use.
struct CaiDraw {
    u32 k0, k1, t, q;
};

CAI_FN CaiWords cai_draw_block(CaiDraw& dr) {
    CaiWords w = cai_philox(dr.t, 0u, CAI_PURPOSE_POLICY, dr.q, dr.k0, dr.k1);
    dr.q += 1u;
    return w;
}

// A uniform integer in [0, high) from one word: floor(w high / 2^32).
CAI_FN int cai_integer_of(u32 w, int high) { return (int)cai_mulhi(w, (u32)high); }

// Two independent standard normals from two words (Box-Muller).
CAI_FN void cai_normal2(u32 w0, u32 w1, real* x1, real* x2) {
    real r = cai_sqrt((real)-2 * cai_log(cai_u01_open(w0)));
    real s, c;
    cai_sincos_turn(cai_u01(w1), &s, &c);
    *x1 = r * c;
    *x2 = r * s;
}

// ------------------------------------------------------------------ gamma and Beta

// Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang 2000), with d = shape - 1/3 and
// c = 1 / sqrt(9 d): a trial from the normal x and the uniform u proposes d v^3, v = 1 + y,
// y = c x, and accepts it when v > 0 and ln u < x^2 / 2 + d (1 - v^3 + ln v^3); the squeeze
// u < 1 - 0.0331 x^4 accepts about eleven trials in twelve without the logarithms, and
// implies the test. The right-hand side is computed as 3 d T(y), T(y) = ln(1 + y) - y +
// y^2 / 2 - y^3 / 3 (the x^2 / 2 cancels exactly): from its series where |y| < 1/16 (every
// trial of a large shape, where the direct form would lose its digits in single precision:
// its terms are near x^2 / 2 and cancel, and a hardware logarithm's absolute error, 2^-22,
// is multiplied by d), directly elsewhere (d < 29 x^2: an error of at most 5e-6 x^2).
struct CaiGammaTrial {
    real y, v3, x2;
    bool pos, squeeze;
};

CAI_FN CaiGammaTrial cai_gamma_propose(real c, real x, real u) {
    CaiGammaTrial tr;
    tr.y = c * x;
    real v = (real)1 + tr.y;
    tr.pos = v > (real)0;
    tr.v3 = v * v * v;
    tr.x2 = x * x;
    tr.squeeze = u < (real)1 - (real)0.0331 * tr.x2 * tr.x2;
    return tr;
}

CAI_FN bool cai_gamma_log_test(real d, const CaiGammaTrial& tr, real u) {
    const real inv_ln2 = (real)1.44269504088896340736;  // the test in base 2: log2 u < rhs / ln 2
    real y = tr.y;
    real p = (real)(1.0 / 9);  // T(y) / y^4 = -1/4 + y/5 - y^2/6 + y^3/7 - y^4/8 + y^5/9 - ...
    p = p * y - (real)(1.0 / 8);
    p = p * y + (real)(1.0 / 7);
    p = p * y - (real)(1.0 / 6);
    p = p * y + (real)(1.0 / 5);
    p = p * y - (real)(1.0 / 4);
    real y2 = y * y;
    real series = ((real)3 * inv_ln2) * d * (y2 * y2) * p;
    real direct = ((real)0.5 * tr.x2 + d * ((real)1 - tr.v3)) * inv_ln2 + d * cai_log2(tr.v3);
    real small = (real)0.0625;
    return cai_log2(u) < (y < small && y > -small ? series : direct);
}

// One trial: whether it is accepted, the proposal in *g. Without a branch: the log test is
// taken whatever the squeeze would say (two logarithms, one instruction each on the GPU).
CAI_FN bool cai_gamma_trial(real d, real c, real x, real u, real* g) {
    CaiGammaTrial tr = cai_gamma_propose(c, x, u);
    *g = d * tr.v3;
    bool lt = cai_gamma_log_test(d, tr, u);
    return tr.pos & lt;  // not &&: no branch
}

// The gamma constants (d, c) of a shape.
struct CaiGammaDC {
    real d, c;
};

CAI_FN CaiGammaDC cai_gamma_dc(real shape) {
    CaiGammaDC out;
    out.d = shape - (real)(1.0 / 3.0);
    out.c = cai_rsqrt((real)9 * out.d);
    return out;
}

// The gamma constants of both shapes of a Beta(a, b).
struct CaiBetaDC {
    CaiGammaDC a, b;
};

// Beta(a_k, b_k) for every arm, as Ga / (Ga + Gb). Arm k's first trials come from one whole
// block (two normals by Box-Muller, two uniforms: one trial for each gamma), so that every
// thread runs the same instructions; a rejected trial is redrawn afterwards, one loop for all
// of them (one copy of the rejection loop in the code, not one per arm), from further blocks
// of two trials each. The squeeze decides about eleven trials in twelve; the others need the
// log test. CAI_LOG_TEST=0 (default): every trial takes the log test alone (it implies the
// squeeze), without a branch; 1: a trial
// takes it where the squeeze leaves it undecided (a branch, which a warp runs when any of its
// threads needs it: nearly always); 2: the undecided trials take it in one loop after the
// arms (a warp runs it as often as its busiest thread needs it). benchmarks/bench_gpu.py
// times the three.
template <class Arm>
CAI_FN void cai_betas(const Arm* arm, real* vals, CaiDraw& dr) {
    real ga[KARMS], gb[KARMS];
    cai_mask bad_a = 0, bad_b = 0;
#if CAI_LOG_TEST == 2
    real ua[KARMS], ub[KARMS];
    CaiGammaTrial ta[KARMS], tb[KARMS];
    cai_mask log_a = 0, log_b = 0;
#endif
    CAI_FOR_ARMS(k) {
        CaiWords w = cai_draw_block(dr);
        real x1, x2;
        cai_normal2(w.w0, w.w1, &x1, &x2);
        real u1 = cai_u01(w.w2), u2 = cai_u01(w.w3);
        bool oka, okb;
#if CAI_LOG_TEST == 0
        oka = cai_gamma_trial(arm[k].a.d, arm[k].a.c, x1, u1, &ga[k]);
        okb = cai_gamma_trial(arm[k].b.d, arm[k].b.c, x2, u2, &gb[k]);
#else
        CaiGammaTrial tra = cai_gamma_propose(arm[k].a.c, x1, u1);
        CaiGammaTrial trb = cai_gamma_propose(arm[k].b.c, x2, u2);
        ga[k] = arm[k].a.d * tra.v3;
        gb[k] = arm[k].b.d * trb.v3;
        oka = tra.pos && tra.squeeze;
        okb = trb.pos && trb.squeeze;
#if CAI_LOG_TEST == 1
        if (tra.pos && !tra.squeeze) oka = cai_gamma_log_test(arm[k].a.d, tra, u1);
        if (trb.pos && !trb.squeeze) okb = cai_gamma_log_test(arm[k].b.d, trb, u2);
#else
        ua[k] = u1;
        ub[k] = u2;
        ta[k] = tra;
        tb[k] = trb;
        log_a |= (cai_mask)(tra.pos && !tra.squeeze) << k;
        log_b |= (cai_mask)(trb.pos && !trb.squeeze) << k;
        oka = tra.pos;  // the undecided ones: after the arms
        okb = trb.pos;
#endif
#endif
        bad_a |= (cai_mask)(!oka) << k;
        bad_b |= (cai_mask)(!okb) << k;
    }
#if CAI_LOG_TEST == 2
    while ((log_a | log_b) != (cai_mask)0) {
        bool is_a = log_a != (cai_mask)0;
        int k = cai_lowest(is_a ? log_a : log_b);
        if (is_a) log_a &= log_a - 1;
        else log_b &= log_b - 1;
        Arm dc = cai_get(arm, k);
        real d = is_a ? dc.a.d : dc.b.d;
        CaiGammaTrial tr = is_a ? cai_get(ta, k) : cai_get(tb, k);
        real u = is_a ? cai_get(ua, k) : cai_get(ub, k);
        bool ok = cai_gamma_log_test(d, tr, u);
        if (is_a) bad_a |= (cai_mask)(!ok) << k;
        else bad_b |= (cai_mask)(!ok) << k;
    }
#endif
    while ((bad_a | bad_b) != (cai_mask)0) {
        bool is_a = bad_a != (cai_mask)0;
        int k = cai_lowest(is_a ? bad_a : bad_b);
        if (is_a) bad_a &= bad_a - 1;
        else bad_b &= bad_b - 1;
        Arm dc = cai_get(arm, k);
        CaiGammaDC shape = is_a ? dc.a : dc.b;
        real y;
        bool ok;
        do {  // two trials a block
            CaiWords w = cai_draw_block(dr);
            real x1, x2, y2;
            cai_normal2(w.w0, w.w1, &x1, &x2);
            ok = cai_gamma_trial(shape.d, shape.c, x1, cai_u01(w.w2), &y);
            bool ok2 = cai_gamma_trial(shape.d, shape.c, x2, cai_u01(w.w3), &y2);
            y = ok ? y : y2;
            ok = ok || ok2;
        } while (!ok);
        if (is_a) cai_set(ga, k, y);
        else cai_set(gb, k, y);
    }
    CAI_FOR_ARMS(k) vals[k] = cai_qdiv(ga[k], ga[k] + gb[k]);
}

// Index of the largest vals[k] over the arms in `mask` (nonempty; its value in *top); ties
// uniformly at random (the j-th tied arm in arm order, j from one word of a block drawn only
// when several arms tie).
CAI_FN int cai_argmax(const real* vals, cai_mask mask, CaiDraw& dr, real* top) {
    real best = -cai_inf();
    CAI_FOR_ARMS(k) if (CAI_HAS(mask, k)) best = cai_max(best, vals[k]);
    cai_mask ties = 0;
    CAI_FOR_ARMS(k) ties |= (cai_mask)(CAI_HAS(mask, k) && vals[k] == best) << k;
    *top = best;
    if (ties == (cai_mask)0) return cai_lowest(mask);  // no value compares equal (NaN)
    if ((ties & (ties - 1)) == (cai_mask)0) return cai_lowest(ties);
    int j = cai_integer_of(cai_draw_block(dr).w0, cai_popc(ties));
    for (; j > 0; --j) ties &= ties - 1;  // drop the j lowest tied arms
    return cai_lowest(ties);
}

// ------------------------------------------------------------------ policy families
//
// A family is a struct (the CPU hooks' counterparts in corraoi/policies/builtin_hooks.py):
// Arm, what the family keeps per arm and recomputes only when the arm is played (set from its
// pulls n and successes s); St, its parameters and per-run state in registers (loaded from
// `prm` and `ps`, the run's column of the state array, at the start of a launch, stored back
// at its end); forced() returns an arm to play whatever the score says, or -1; score() writes
// the index of every arm into vals (the candidate set is applied after); update() runs after
// the slot with the counts updated.

// What a family's functions see of the run at slot t: lt = ln t, `first`: the launch's first
// slot, `unpulled`: the arms never played.
struct CaiSlot {
    u32 t;
    real lt;
    bool first;
    cai_mask unpulled;
};

struct CaiState {
    double* base;
    i64 stride;
    CAI_METHOD double& operator[](i64 i) const { return base[i * stride]; }
};

struct CaiNoArm {
    template <class St>
    CAI_METHOD void set(u32, u32, const St&) {}
};

struct CaiNoState {
    CAI_METHOD void load(CaiState, const double*, const CaiSlot&) {}
    CAI_METHOD void store(CaiState) const {}
};

#define CAI_FORCED_ARGS const CaiSlot &sl, St &st, CaiDraw &dr
#define CAI_SCORE_ARGS                                                                        \
    const CaiSlot &sl, const real *mu, const Arm *arm, real *vals, St &st, CaiDraw &dr
#define CAI_UPDATE_ARGS const CaiSlot &sl, int played, int rew, St &st, CaiState ps

CAI_FN int cai_first_unpulled(const CaiSlot& sl) {
    if (sl.unpulled == (cai_mask)0) return -1;  // every slot after the first K
    return cai_lowest(sl.unpulled);
}

// Krishnasamy et al. (2021): explore w.p. min(1, 3 K ln^2 t / t), an arm uniformly at random.
// The coin and the arm of slot t are words 2i and 2i + 1 of block ((t - 1) / 2, EXPLORE),
// i = (t - 1) mod 2, kept in *eb between the two slots.
CAI_FN int cai_explore(const CaiSlot& sl, CaiWords* eb, const CaiDraw& dr) {
    u32 tm1 = sl.t - 1u;
    if (sl.first || (tm1 & 1u) == 0u)
        *eb = cai_philox(tm1 >> 1, 0u, CAI_PURPOSE_EXPLORE, 0u, dr.k0, dr.k1);
    if (sl.t < 2u) return -1;
    bool second = (tm1 & 1u) != 0u;
    u32 coin = second ? eb->w2 : eb->w0;
    u32 pick = second ? eb->w3 : eb->w1;
    real prob = cai_qdiv((real)(3 * KARMS) * sl.lt * sl.lt, (real)sl.t);  // a coin's odds
    if ((real)coin * (real)2.3283064365386963e-10 < prob) return cai_integer_of(pick, KARMS);
    return -1;
}

// Beta(S + 1, F + 1) posteriors: the gamma constants of both shapes, per arm.
struct CaiBetaArm : CaiBetaDC {
    template <class St>
    CAI_METHOD void set(u32 n, u32 s, const St&) {
        a = cai_gamma_dc((real)s + (real)1);
        b = cai_gamma_dc((real)(n - s) + (real)1);
    }
};

// UCB: each arm once, then argmax mu_hat + sqrt(c ln t / n_k).    params: c
struct UcbForm {
    struct Arm {
        real rsq;  // 1 / sqrt(n)
        template <class St>
        CAI_METHOD void set(u32 n, u32, const St&) { rsq = cai_rsqrt((real)n); }
    };
    struct St {
        real c;
        CAI_METHOD void load(CaiState, const double* prm, const CaiSlot&) { c = (real)prm[0]; }
        CAI_METHOD void store(CaiState) const {}
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_first_unpulled(sl); }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        real b = cai_sqrt(st.c * sl.lt);
        CAI_FOR_ARMS(k) vals[k] = mu[k] + b * arm[k].rsq;
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Thompson sampling, Beta(S + 1, F + 1).
struct TsBetaForm {
    typedef CaiBetaArm Arm;
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_betas(arm, vals, dr); }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Thompson sampling, N(mu_hat, beta / (n + 1)).                   params: beta
struct TsGaussForm {
    struct St {
        real beta;
        CAI_METHOD void load(CaiState, const double* prm, const CaiSlot&) {
            beta = (real)prm[0];
        }
        CAI_METHOD void store(CaiState) const {}
    };
    struct Arm {
        real sd;  // sqrt(beta / (n + 1))
        CAI_METHOD void set(u32 n, u32, const St& st) {
            sd = cai_sqrt(cai_qdiv(st.beta, (real)n + (real)1));
        }
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CaiWords w = {0u, 0u, 0u, 0u};
        CAI_FOR_ARMS(k) {
            if (k % 4 == 0) w = cai_draw_block(dr);  // a block gives the normals of 4 arms
            if (k % 2 == 0) {
                real x1, x2;
                cai_normal2(k % 4 == 0 ? w.w0 : w.w2, k % 4 == 0 ? w.w1 : w.w3, &x1, &x2);
                vals[k] = mu[k] + arm[k].sd * x1;
                if (k + 1 < KARMS) vals[k + 1] = mu[k + 1] + arm[k + 1].sd * x2;
            }
        }
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Q-UCB: explore, else each arm once, then argmax mu_hat + sqrt(ln^2 t / (2 n_k)).
struct QUcbForm {
    struct Arm {
        real rsq2;  // 1 / sqrt(2 n)
        template <class St>
        CAI_METHOD void set(u32 n, u32, const St&) { rsq2 = cai_rsqrt((real)2 * (real)n); }
    };
    struct St : CaiNoState {
        CaiWords eb;  // the exploration block of this slot and the next
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) {
        int a = cai_explore(sl, &st.eb, dr);
        return a >= 0 ? a : cai_first_unpulled(sl);
    }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CAI_FOR_ARMS(k) vals[k] = mu[k] + sl.lt * arm[k].rsq2;  // sqrt(lt^2 / 2n), lt >= 0
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Q-TS: explore, else Beta(S + 1, F + 1) sampling.
struct QTsForm {
    typedef CaiBetaArm Arm;
    struct St : CaiNoState {
        CaiWords eb;
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_explore(sl, &st.eb, dr); }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_betas(arm, vals, dr); }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Sliding-window UCB (Garivier and Moulines 2011).                params: window, c
// ps: [0, K) pulls in the window, [K, 2K) successes in the window (in registers during a
// launch, as floats: exact below 2^24 > the largest window), then a ring of the last `window`
// slots, 2 (arm + 1) + reward each (0 = empty), held as the bits of an int64.
struct SwUcbForm {
    typedef CaiNoArm Arm;
    struct St {
        real n[KARMS], s[KARMS];
        u32 window, pos;  // pos: (t - 1) mod window, the ring's entry of slot t
        real c, lw;       // lw = ln(window)
        CAI_METHOD void load(CaiState ps, const double* prm, const CaiSlot& sl) {
            CAI_FOR_ARMS(k) {
                n[k] = (real)ps[k];
                s[k] = (real)ps[KARMS + k];
            }
            window = (u32)prm[0];
            c = (real)prm[1];
            lw = (real)log(prm[0]);
            pos = (sl.t - 1u) % window;
        }
        CAI_METHOD void store(CaiState ps) const {
            CAI_FOR_ARMS(k) {
                ps[k] = (double)n[k];
                ps[KARMS + k] = (double)s[k];
            }
        }
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        real lt = sl.t > 1u ? (sl.t < st.window ? sl.lt : st.lw) : (real)0;
        real b = cai_sqrt(st.c * lt);
        CAI_FOR_ARMS(k) {
            real rsq = cai_rsqrt(st.n[k]);  // infinite when n = 0: the index then is too
            vals[k] = st.n[k] == (real)0 ? cai_inf() : (st.s[k] * rsq + b) * rsq;
        }
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        double& slot = ps[2 * KARMS + st.pos];
        int old = (int)cai_bits_of(slot);
        int old_arm = (old >> 1) - 1;  // -1: empty
        real old_rew = (real)(old & 1);
        CAI_FOR_ARMS(k) {  // selects (as in cai_set): the arrays stay in registers
            st.n[k] = k == old_arm ? st.n[k] - (real)1 : st.n[k];
            st.s[k] = k == old_arm ? st.s[k] - old_rew : st.s[k];
            st.n[k] = k == played ? st.n[k] + (real)1 : st.n[k];
            st.s[k] = k == played ? st.s[k] + (real)rew : st.s[k];
        }
        slot = cai_double_of((i64)(2 * (played + 1) + rew));
        st.pos = st.pos + 1u == st.window ? 0u : st.pos + 1u;
    }
};

// Discounted Thompson sampling (Raj and Kalyani 2017).            params: gamma
// ps: [0, K) discounted successes, [K, 2K) discounted failures (in registers during a launch).
struct DTsForm {
    typedef CaiNoArm Arm;
    struct St {
        real s[KARMS], f[KARMS];
        real gamma;
        CAI_METHOD void load(CaiState ps, const double* prm, const CaiSlot&) {
            CAI_FOR_ARMS(k) {
                s[k] = (real)ps[k];
                f[k] = (real)ps[KARMS + k];
            }
            gamma = (real)prm[0];
        }
        CAI_METHOD void store(CaiState ps) const {
            CAI_FOR_ARMS(k) {
                ps[k] = (double)s[k];
                ps[KARMS + k] = (double)f[k];
            }
        }
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CaiBetaDC dc[KARMS];
        CAI_FOR_ARMS(k) {
            dc[k].a = cai_gamma_dc(st.s[k] + (real)1);
            dc[k].b = cai_gamma_dc(st.f[k] + (real)1);
        }
        cai_betas(dc, vals, dr);
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        CAI_FOR_ARMS(k) {
            st.s[k] *= st.gamma;
            st.f[k] *= st.gamma;
            st.s[k] = k == played ? st.s[k] + (real)rew : st.s[k];
            st.f[k] = k == played ? st.f[k] + (real)(1 - rew) : st.f[k];
        }
    }
};

// ------------------------------------------------------------------ one run

// Arrays of per-run values are laid out [field][run] (`R` runs), so that the threads of a
// warp read and write neighbouring addresses. `lnt[j]` is ln(t0 + j + 1); `thr` the CDF rows
// of the n hidden states (cai_hidden); `ymask[x]` the arms that succeed in state x (bit
// k: Y[k][x] = 1); `comb` is candidates.candidate_bitsets (K, 8) for the correlated forms.
// At the checkpoint slots `ck_t` (the launch's, ascending), each run's regret and AoI sum go
// to ck_reg and ck_asum, laid out [checkpoint][run], and its pulls to ck_pulls,
// [checkpoint][arm][run] (reduce_checkpoints sums them over the runs).
#define CAI_PARAMS                                                                            \
    int R, u64 seed0, i64 t0, i64 nslots, const double *lnt, int n, int nrows, int kind,      \
        const u32 *thr, const i64 *trace, const u64 *ymask, const u64 *comb, int best,        \
        const double *prm, int S, i64 *pulls, i64 *succ, double *pstate, int *xprev,          \
        i64 *age_a, i64 *oage_a, i64 *reg_a, i64 *asum_a, int nck, const i64 *ck_t,           \
        i64 *ck_reg, i64 *ck_asum, u32 *ck_pulls, int cap_run, i64 *cap
#define CAI_NAMES                                                                             \
    R, seed0, t0, nslots, lnt, n, nrows, kind, thr, trace, ymask, comb, best, prm, S, pulls,  \
        succ, pstate, xprev, age_a, oage_a, reg_a, asum_a, nck, ck_t, ck_reg, ck_asum,        \
        ck_pulls, cap_run, cap

// The per-slot capture of run `cap_run` (-1: none), CAI_CAPW values a slot of this launch into
// `cap`: the hidden state, the arm, the reward, the ages (own, oracle's), the regret and the
// AoI sum after the slot, the override flag and the candidate set as a bit mask (K <= 64);
// and, compiled with CAI_CAPTURE=1 only, why the arm was played, as the CPU engine's record
// defines it (corraoi/engine/_kernel.py): the forced flag (not chosen by the score: the
// policy forced it and the override did not act), the override's threshold 1 / max mu_hat
// before the slot (+infinity while every mean is 0) and the score of each arm (what the
// policy maximised; NaN outside the candidate set and at a slot not scored), as float32 bits
// in the low word. Those are values the slot already has in registers: capturing them draws
// nothing and changes no decision, and a sweep's module (CAI_CAPTURE=0) is compiled from the
// same text as before they existed. What `corraoi record --from` of a GPU sweep turns into
// the slots of one run. The row's layout is corraoi.engine.slot_record.GPU_CAPTURE_ROW (each
// `row[i] =` below names its field in a comment, `row[i + k] =` a per-arm field of KARMS
// words; tests/test_slot_record.py checks the two agree).
#if CAI_CAPTURE
#define CAI_CAPW (11 + KARMS)

CAI_FN i64 cai_f32_word(float v) {  // float32 bits, in the low word
#if defined(__CUDACC__)
    return (i64)__float_as_uint(v);
#else
    u32 b;
    memcpy(&b, &v, sizeof b);
    return (i64)b;
#endif
}
#else
#define CAI_CAPW 9
#endif

// The hidden state of slot t from its word w (w / 2^32 a uniform), through the CDF of row 0
// (X_1 and every X_t of an i.i.d. channel) or of row X_{t-1} + 1 (Markov). `thr` holds a row
// per CDF, `m` = 4 + 4 ceil((n - 1) / 4) words each: h, then three unused words, then
// thr_i = ceil(cdf_i 2^32) for the h first states i < n - 1 with thr_i < 2^32, padded with
// 2^32 - 1 (corraoi/gpu/runner.py, hidden_table). X is the number of thresholds <= w, at
// most h: every comparison at once, four words a load (no chain of dependent loads; the
// rows of an i.i.d. channel are the same address for a whole warp).
struct CaiWords4 {
    u32 x, y, z, w;
};

CAI_FN CaiWords4 cai_load4(const u32* p) {  // p 16-byte aligned: one 16-byte load on the GPU
#if defined(__CUDACC__)
    uint4 v = *(const uint4*)p;
    CaiWords4 out = {v.x, v.y, v.z, v.w};
#else
    CaiWords4 out = {p[0], p[1], p[2], p[3]};
#endif
    return out;
}

CAI_FN int cai_count4(u32 w, const CaiWords4& v) {
    return (w >= v.x ? 1 : 0) + (w >= v.y ? 1 : 0) + (w >= v.z ? 1 : 0) + (w >= v.w ? 1 : 0);
}

CAI_FN int cai_hidden(u32 w, const u32* thr, int m, int nrows, int xp) {
    const u32* c = thr + (nrows > 1 && xp >= 0 ? (xp + 1) * m : 0);
    int h = (int)c[0];
    int x = 0;
#if defined(__CUDACC__)
#pragma unroll 1
#endif
    for (int i = 4; i < m; i += 4) {
        x += cai_count4(w, cai_load4(c + i));
    }
    return x < h ? x : h;  // a padding word counts only for w = 2^32 - 1, when x >= h
}

template <class P, int CORR, int AWARE>
CAI_FN void cai_run(int r, const u64* comb_tab, CAI_PARAMS) {
    typedef typename P::Arm Arm;
    typedef typename P::St St;
    u64 seed = seed0 + (u64)r;
    CaiDraw dr;
    dr.k0 = (u32)seed;
    dr.k1 = (u32)(seed >> 32);
    CaiState ps = {pstate + r, (i64)R};
    CaiSlot sl;
    sl.t = (u32)t0 + 1u;
    sl.first = true;
    St st;
    st.load(ps, prm, sl);
    u32 np[KARMS], ns[KARMS];  // pulls and successes: at most T < 2^32 (limits.MAX_HORIZON)
    real mu[KARMS], vals[KARMS];
    Arm arm_of[KARMS];
    cai_mask unpulled = 0;
    CAI_FOR_ARMS(k) {
        np[k] = (u32)pulls[(i64)k * R + r];
        ns[k] = (u32)succ[(i64)k * R + r];
        mu[k] = np[k] > 0u ? (real)ns[k] / (real)np[k] : (real)0;
        arm_of[k].set(np[k], ns[k], st);
        unpulled |= (cai_mask)(np[k] == 0u) << k;
        vals[k] = (real)0;
    }
    u32 age = (u32)age_a[r], oage = (u32)oage_a[r];
    i64 asum = asum_a[r], osum = asum - reg_a[r];  // AoI sums, own and the oracle's
    int xp = xprev[r];
    int ci = 0;
    while (ci < nck && ck_t[ci] <= t0) ++ci;
    u32 next_ck = ci < nck ? (u32)ck_t[ci] : 0u;  // 0: none (t >= 1)
    const u32 t_end = (u32)(t0 + nslots);
    const int m = 4 + 4 * ((n + 2) / 4);  // words of a row of thr
    // an i.i.d. channel of at most 5 states: its one row of thresholds in registers
    const bool iid4 = kind != 1 && nrows == 1 && m == 8;
    const int h0 = iid4 ? (int)thr[0] : 0;
    const CaiWords4 thr0 = iid4 ? cai_load4(thr + 4) : CaiWords4{0u, 0u, 0u, 0u};
    CaiWords hb = {0u, 0u, 0u, 0u};  // the hidden block of slots 4b + 1 .. 4b + 4
    for (u32 t = (u32)t0 + 1u; t <= t_end; ++t) {
        u32 j = t - (u32)t0 - 1u;
        sl.t = t;
        sl.lt = (real)lnt[j];
        sl.first = j == 0u;
        sl.unpulled = unpulled;
        dr.t = t;
        dr.q = 0u;
        u32 tm1 = t - 1u;
        int x;
        if (kind == 1) {
            x = (int)trace[tm1];
        } else {
            if (sl.first || (tm1 & 3u) == 0u) {
                hb = cai_philox(tm1 >> 2, 0u, CAI_PURPOSE_HIDDEN, 0u, dr.k0, dr.k1);
                for (u32 i = 0; i < (tm1 & 3u); ++i) {  // a launch that starts inside a block
                    hb.w0 = hb.w1;
                    hb.w1 = hb.w2;
                    hb.w2 = hb.w3;
                }
            }
            u32 w = hb.w0;  // this slot's word; the next slot's moves up (moves, not selects)
            hb.w0 = hb.w1;
            hb.w1 = hb.w2;
            hb.w2 = hb.w3;
            if (iid4) {
                x = cai_count4(w, thr0);
                x = x < h0 ? x : h0;
            } else {
                x = cai_hidden(w, thr, m, nrows, xp);
            }
        }
        xp = x;
        cai_mask cand = CAI_ALL_ARMS;
        int forced = P::forced(sl, st, dr);
        if (CORR && forced < 0) {
            // S_t: arms pulled at least (t - 1) / K times; k_emp the best of them; A_t the
            // arms whose pseudo-reward estimate against every pulled arm of S_t reaches
            // mu_hat[k_emp]: the arms a pulled l of S_t rules out are comb[l][code], code
            // saying which of 0, l's failure rate and l's success rate fall below the target.
            // The comparisons are exact, in integers: s_e / n_e > (n_l - s_l) / n_l and
            // s_e / n_e > s_l / n_l as products (k_emp = e), so no rounding can move an arm in
            // or out of the set.
            u32 need = tm1 / (u32)KARMS;  // n K >= t - 1: n >= ceil((t - 1) / K)
            need += need * (u32)KARMS != tm1 ? 1u : 0u;
            cai_mask in_s = 0;
            CAI_FOR_ARMS(k) in_s |= (cai_mask)(np[k] >= need) << k;
            int kemp;
            cai_mask out = 0;
            if ((in_s & (in_s - 1)) == (cai_mask)0) {
                // one arm in S_t (the usual case): it is k_emp (no tie, no draw) and the only
                // arm that rules others out, never below its own mean: the same set as below
                kemp = cai_lowest(in_s);
                u32 se = cai_get(ns, kemp), ne = cai_get(np, kemp);
                int code = (se > 0u ? 1 : 0) | (se > ne - se ? 2 : 0);
                if (ne > 0u) out = (cai_mask)comb_tab[kemp * 8 + code];
            } else {
                real top;
                kemp = cai_argmax(mu, in_s, dr, &top);
                u64 se = cai_get(ns, kemp), ne = cai_get(np, kemp);
                CAI_FOR_ARMS(l) {
                    if (CAI_HAS(in_s, l) && np[l] > 0u) {
                        u64 nl = np[l], sl_ = ns[l];
                        int code = (se > 0u ? 1 : 0) | (se * nl > (nl - sl_) * ne ? 2 : 0) |
                                   (se * nl > sl_ * ne ? 4 : 0);
                        out |= (cai_mask)comb_tab[l * 8 + code];
                    }
                }
            }
            cand = (CAI_ALL_ARMS & ~out) | CAI_BIT(kemp);
        }
        bool override_ = false;
        int arm;
        real top;
#if CAI_CAPTURE
        real cap_max = (real)0;  // max mu_hat before the slot: the override's threshold
        CAI_FOR_ARMS(k) cap_max = cai_max(cap_max, mu[k]);
#endif
        if (AWARE) {
            real maxmu = (real)0;
            CAI_FOR_ARMS(k) maxmu = cai_max(maxmu, mu[k]);
            override_ = maxmu > (real)0 && (real)age * maxmu > (real)1;
        }
        if (override_) {
            arm = cai_argmax(mu, CAI_ALL_ARMS, dr, &top);
        } else if (forced >= 0) {
            arm = forced;
        } else {
            P::score(sl, mu, arm_of, vals, st, dr);
            arm = cai_argmax(vals, cand, dr, &top);
        }
        cai_mask ym = (cai_mask)ymask[x];
        int rew = (int)((ym >> arm) & (cai_mask)1);
        int orew = (int)((ym >> best) & (cai_mask)1);
        {  // the played arm's values, recomputed for it alone
            u32 n1 = cai_get(np, arm) + 1u;
            u32 s1 = cai_get(ns, arm) + (u32)rew;
            real m1 = (real)s1 / (real)n1;
            Arm a1;
            a1.set(n1, s1, st);
            cai_set(np, arm, n1);
            cai_set(ns, arm, s1);
            cai_set(mu, arm, m1);
            cai_set(arm_of, arm, a1);
            unpulled &= ~CAI_BIT(arm);
        }
        P::update(sl, arm, rew, st, ps);
        age = rew == 1 ? 1u : age + 1u;
        oage = orew == 1 ? 1u : oage + 1u;
        asum += (i64)age;
        osum += (i64)oage;
        if (r == cap_run) {
            i64* row = cap + (i64)j * CAI_CAPW;
            row[0] = x;                   // x
            row[1] = arm;                 // arm
            row[2] = rew;                 // success
            row[3] = age;                 // aoi
            row[4] = oage;                // oracle_aoi
            row[5] = asum - osum;         // regret
            row[6] = asum;                // aoisum
            row[7] = override_ ? 1 : 0;   // override
            row[8] = (i64)cand;           // candidates
#if CAI_CAPTURE
            const bool scored = !override_ && forced < 0;
            const i64 nan_word = 0x7fc00000, inf_word = 0x7f800000;  // float32 NaN, +infinity
            const i64 thr = cap_max > (real)0 ? cai_f32_word((float)((real)1 / cap_max)) : inf_word;
            row[9] = forced >= 0 && !override_ ? 1 : 0;  // forced
            row[10] = thr;                               // override_threshold
            CAI_FOR_ARMS(k) {
                bool on = scored && CAI_HAS(cand, k);
                row[11 + k] = on ? cai_f32_word((float)vals[k]) : nan_word;     // score
            }
#endif
        }
        if (t == next_ck) {
            ck_reg[(i64)ci * R + r] = asum - osum;
            ck_asum[(i64)ci * R + r] = asum;
            CAI_FOR_ARMS(k) ck_pulls[((i64)ci * KARMS + k) * R + r] = np[k];
            ++ci;
            next_ck = ci < nck ? (u32)ck_t[ci] : 0u;
        }
    }
    CAI_FOR_ARMS(k) {
        pulls[(i64)k * R + r] = (i64)np[k];
        succ[(i64)k * R + r] = (i64)ns[k];
    }
    st.store(ps);
    age_a[r] = age;
    oage_a[r] = oage;
    reg_a[r] = asum - osum;
    asum_a[r] = asum;
    xprev[r] = xp;
}

// ------------------------------------------------------------------ entry points
//
// advance_<family>_<c><a>: c = 1 for the correlated form, a = 1 for the AoI-aware one (each
// its own entry point, so that a form's registers are only what it uses). The correlated
// forms read the candidate bitsets from shared memory (a block loads them once).

#if defined(__CUDACC__)
#define CAI_ENTRY1(NAME, FORM, C, A)                                                          \
    extern "C" __global__ void advance_##NAME##_##C##A(CAI_PARAMS) {                          \
        const u64* tab = comb;                                                                \
        if (C) {                                                                              \
            __shared__ u64 s_comb[KARMS * 8];                                                 \
            for (int i = threadIdx.x; i < KARMS * 8; i += blockDim.x) s_comb[i] = comb[i];    \
            __syncthreads();                                                                  \
            tab = s_comb;                                                                     \
        }                                                                                     \
        int r = blockIdx.x * blockDim.x + threadIdx.x;                                        \
        if (r < R) cai_run<FORM, C, A>(r, tab, CAI_NAMES);                                    \
    }
#else
#define CAI_ENTRY1(NAME, FORM, C, A)                                                          \
    extern "C" void advance_##NAME##_##C##A(CAI_PARAMS) {                                     \
        _Pragma("omp parallel for schedule(static)") for (int r = 0; r < R; ++r)              \
            cai_run<FORM, C, A>(r, comb, CAI_NAMES);                                          \
    }
#endif
#define CAI_ENTRY2(NAME, FORM) CAI_ENTRY1(NAME, FORM, 0, 0) CAI_ENTRY1(NAME, FORM, 0, 1)
#define CAI_ENTRY4(NAME, FORM)                                                                \
    CAI_ENTRY2(NAME, FORM) CAI_ENTRY1(NAME, FORM, 1, 0) CAI_ENTRY1(NAME, FORM, 1, 1)

// The order of FAMILIES in corraoi/gpu/device.py (CAI_FAMILY is its index plus one).
#if CAI_WANT(1)
CAI_ENTRY4(ucb, UcbForm)
#endif
#if CAI_WANT(2)
CAI_ENTRY4(ts_beta, TsBetaForm)
#endif
#if CAI_WANT(3)
CAI_ENTRY4(ts_gauss, TsGaussForm)
#endif
#if CAI_WANT(4)
CAI_ENTRY4(q_ucb, QUcbForm)
#endif
#if CAI_WANT(5)
CAI_ENTRY4(q_ts, QTsForm)
#endif
#if CAI_WANT(6)
CAI_ENTRY2(sw_ucb, SwUcbForm)
#endif
#if CAI_WANT(7)
CAI_ENTRY2(d_ts, DTsForm)
#endif

// ------------------------------------------------------------------ checkpoint sums
//
// reduce_checkpoints sums what a launch wrote at its checkpoints over the runs, in one pass
// and exactly, in integers: CAI_CKW words a checkpoint of `acc` (zeroed by the host before the
// first launch and read once after the last):
//
//   words 0-4    the regret: its sum (2 words, the lowest first: two's complement mod 2^128)
//                and the sum of its squares (3 words)
//   words 5-9    the AoI sum, likewise (the estimator is it minus t / mu*, the same in every run)
//   words 10-14  the regret minus the baseline's (`base`, run by run; flag CAI_CK_BASE), likewise
//   words 15..   the pulls of each arm
//
// and, with flag CAI_CK_KEEP, copies each run's regret to `kept` (a baseline's runs). Every
// value is below 2^63 in size (limits.MAX_HORIZON), so a square is below 2^126 and no sum can
// overflow. Sums of integers do not depend on the order of addition: the moments that the host
// makes of them (corraoi/gpu/runner.py) are the same whatever the launch shape, the blocks or
// the order of the atomics, and are exact (sum(x^2) - sum(x)^2 / n in exact integers, rounded
// once), so no cancellation in them. A thread adds its runs, a warp's threads merge theirs (a
// tree of shuffles), and its first lane adds the warp's into `acc` with 64-bit atomics, carries
// passed on word by word. The emulated device runs the same additions, merges and atomics, with
// the warp's lanes as an array.
#define CAI_CKW (15 + KARMS)
#define CAI_CK_BASE 1
#define CAI_CK_KEEP 2

CAI_FN u64 cai_mulhi64(u64 a, u64 b) {
#if defined(__CUDACC__)
    return __umul64hi(a, b);
#else
    return (u64)(((unsigned __int128)a * b) >> 64);
#endif
}

CAI_FN u64 cai_atomic_add(u64* p, u64 v) {  // returns the value before
#if defined(__CUDACC__)
    return atomicAdd((unsigned long long*)p, (unsigned long long)v);
#else
    return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
#endif
}

// a += x (five words: the sum, the sum of squares).
CAI_FN void cai_sum_add(u64* a, i64 x) {
    u64 lo = (u64)x;
    u64 s = a[0] + lo;
    a[1] += (x < 0 ? ~0ull : 0ull) + (s < lo ? 1ull : 0ull);
    a[0] = s;
    u64 u = x < 0 ? 0ull - (u64)x : (u64)x;  // |x| <= 2^63
    u64 q0 = u * u, q1 = cai_mulhi64(u, u);    // q1 < 2^62: q1 + carry does not wrap
    u64 s2 = a[2] + q0;
    u64 add = q1 + (s2 < q0 ? 1ull : 0ull);
    u64 s3 = a[3] + add;
    a[4] += s3 < add ? 1ull : 0ull;
    a[2] = s2;
    a[3] = s3;
}

// a += b as integers of W words, the lowest first.
template <int W>
CAI_FN void cai_wide_add(u64* a, const u64* b) {
    u64 carry = 0;
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int i = 0; i < W; ++i) {
        u64 v = b[i] + carry;
        u64 c = v < carry ? 1ull : 0ull;  // b[i] = 2^64 - 1 and a carry in
        u64 s = a[i] + v;
        carry = c + (s < v ? 1ull : 0ull);
        a[i] = s;
    }
}

// The same into memory that other threads add to at the same time: an atomic a word, the
// carry out of each (known from the value before) added to the next.
template <int W>
CAI_FN void cai_atomic_wide_add(u64* p, const u64* b) {
    u64 carry = 0;
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int i = 0; i < W; ++i) {
        u64 v = b[i] + carry;
        carry = v < carry ? 1ull : 0ull;
        if (v != 0ull) {
            u64 old = cai_atomic_add(p + i, v);
            carry += old + v < old ? 1ull : 0ull;
        }
    }
}

// One run's values at checkpoint c (its row of the buffers) into a thread's words a.
CAI_FN void cai_ck_run(u64* a, int c, i64 r, int R, const i64* ck_reg, const i64* ck_asum,
                       const u32* ck_pulls, const i64* base, i64* kept, int flags) {
    i64 at = (i64)c * R + r;
    i64 reg = ck_reg[at];
    cai_sum_add(a, reg);
    cai_sum_add(a + 5, ck_asum[at]);
    if (flags & CAI_CK_BASE) cai_sum_add(a + 10, reg - base[at]);
    if (flags & CAI_CK_KEEP) kept[at] = reg;
    CAI_FOR_ARMS(k) a[15 + k] += (u64)ck_pulls[((i64)c * KARMS + k) * R + r];
}

CAI_FN void cai_ck_merge(u64* a, const u64* b) {
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int q = 0; q < 15; q += 5) {
        cai_wide_add<2>(a + q, b + q);
        cai_wide_add<3>(a + q + 2, b + q + 2);
    }
    CAI_FOR_ARMS(k) a[15 + k] += b[15 + k];
}

CAI_FN void cai_ck_flush(u64* acc, const u64* a) {
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int q = 0; q < 15; q += 5) {
        cai_atomic_wide_add<2>(acc + q, a + q);
        cai_atomic_wide_add<3>(acc + q + 2, a + q + 2);
    }
    CAI_FOR_ARMS(k) if (a[15 + k] != 0ull) cai_atomic_add(acc + 15 + k, a[15 + k]);
}

// `nck` checkpoints of `R` runs: ck_reg, ck_asum, ck_pulls, `base` and `kept` from the
// group's first checkpoint, `acc` its CAI_CKW words. On the GPU: a block of a multiple of 32
// threads for (checkpoint blockIdx.x, runs blockIdx.y + gridDim.y i ...).
#if defined(__CUDACC__)
extern "C" __global__ void reduce_checkpoints(int R, int nck, const i64* ck_reg,
                                              const i64* ck_asum, const u32* ck_pulls,
                                              const i64* base, i64* kept, int flags, u64* acc) {
    const int c = blockIdx.x;
    u64 a[CAI_CKW];
#pragma unroll
    for (int w = 0; w < CAI_CKW; ++w) a[w] = 0ull;
    const i64 step = (i64)gridDim.y * blockDim.x;
    for (i64 r = (i64)blockIdx.y * blockDim.x + threadIdx.x; r < R; r += step)
        cai_ck_run(a, c, r, R, ck_reg, ck_asum, ck_pulls, base, kept, flags);
#pragma unroll
    for (int off = 16; off > 0; off >>= 1) {
        u64 b[CAI_CKW];
#pragma unroll
        for (int w = 0; w < CAI_CKW; ++w) b[w] = __shfl_down_sync(0xffffffffu, a[w], off);
        cai_ck_merge(a, b);
    }
    if ((threadIdx.x & 31u) == 0u) cai_ck_flush(acc + (i64)c * CAI_CKW, a);
}
#else
extern "C" void reduce_checkpoints(int R, int nck, const i64* ck_reg, const i64* ck_asum,
                                   const u32* ck_pulls, const i64* base, i64* kept, int flags,
                                   u64* acc) {
    const int lanes = 32, per_lane = 8;  // a warp's threads, each adding every 32nd run
    const i64 span = (i64)lanes * per_lane, spans = ((i64)R + span - 1) / span;
    _Pragma("omp parallel for schedule(static)") for (i64 job = 0; job < (i64)nck * spans;
                                                       ++job) {
        int c = (int)(job / spans);
        i64 r0 = (job % spans) * span;
        u64 a[32][CAI_CKW];
        memset(a, 0, sizeof a);
        for (i64 r = r0; r < r0 + span && r < R; ++r)
            cai_ck_run(a[r % lanes], c, r, R, ck_reg, ck_asum, ck_pulls, base, kept, flags);
        for (int off = 16; off > 0; off >>= 1)
            for (int l = 0; l < off; ++l) cai_ck_merge(a[l], a[l + off]);
        cai_ck_flush(acc + (i64)c * CAI_CKW, a[0]);
    }
}
#endif

// The Beta sampler as Thompson sampling runs it (cai_betas), for its tests: out[i] is arm 0's
// sample in slot i + 1 of the run with seed `seed` when every arm's posterior is
// Beta(a[i], b[i]), a, b >= 1.
#if CAI_WANT(2)
#if defined(__CUDACC__)
extern "C" __global__ void beta_draws(const double* a, const double* b, int count, u64 seed,
                                      double* out) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= count) return;
#else
extern "C" void beta_draws(const double* a, const double* b, int count, u64 seed, double* out) {
    _Pragma("omp parallel for schedule(static)") for (int i = 0; i < count; ++i) {
#endif
    CaiBetaDC arm[KARMS];
    CAI_FOR_ARMS(k) {
        arm[k].a = cai_gamma_dc((real)a[i]);
        arm[k].b = cai_gamma_dc((real)b[i]);
    }
    CaiDraw dr = {(u32)seed, (u32)(seed >> 32), (u32)i + 1u, 0u};
    real vals[KARMS];
    cai_betas(arm, vals, dr);
    out[i] = (double)vals[0];
#if !defined(__CUDACC__)
    }
#endif
}
#endif

// Known-answer check of the generator: in[6 i .. 6 i + 5] = counter (4 words), key (2 words).
#if defined(__CUDACC__)
extern "C" __global__ void philox_kat(const u32* in, u32* out, int count) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= count) return;
#else
extern "C" void philox_kat(const u32* in, u32* out, int count) {
    for (int i = 0; i < count; ++i) {
#endif
    const u32* a = in + 6 * i;
    CaiWords w = cai_philox(a[0], a[1], a[2], a[3], a[4], a[5]);
    out[4 * i] = w.w0;
    out[4 * i + 1] = w.w1;
    out[4 * i + 2] = w.w2;
    out[4 * i + 3] = w.w3;
#if !defined(__CUDACC__)
    }
#endif
}
