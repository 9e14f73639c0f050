// corraoi's GPU kernels: one CUDA thread per run, every built-in policy family.
//
// CuPy compiles this file with NVRTC (corraoi/gpu/device.py); the same text also compiles as
// plain C++ (the emulated device: a loop over runs instead of a thread grid), so that the
// policy logic is tested on machines without a GPU. Compile-time constants: KARMS (arms) and,
// optionally, CAI_FAMILY (compile one family's entry points only: its index in FAMILIES of
// device.py, plus one; 0 or unset: all).
//
// Per run, per slot (the CPU kernel corraoi/engine/_kernel.py does the same in the same order):
// draw the hidden state from the run's hidden stream, let the policy force an arm, restrict
// to the correlated candidate set (correlated forms), apply the AoI-aware override (aware
// forms), else play the argmax of the policy's score over the candidates (ties uniformly at
// random); then update counts, ages and the policy's state.
//
// Random numbers: Philox4x32-10 (Salmon, Moraes, Dror, Shaw 2011), keyed by the run's 64-bit
// seed. The counter names the purpose: (slot, HIDDEN) draws the hidden state of a slot, so
// every policy sees the same path for a seed and nothing depends on the launch shape; the
// policy's draws come from (position, POLICY), a stream whose position is saved between
// launches. Sums are 64-bit (AoI sums pass 2^31 near T = 1.3e9); pulls and successes of an
// arm, at most T < 2^32, are 32-bit in registers and 64-bit in memory.
//
// Written for the GPU's habits (docs/gpu.md, "How the kernel is written"): a run's per-arm
// values live in registers (every loop over the arms is unrolled and an arm chosen at run
// time is read and written through comparisons, never an index), sets of arms are bit masks,
// what changes only when an arm is played (its mean, the constants of its index or of its
// posterior's gamma draws) is recomputed for that arm alone, ln t comes from a per-launch
// table (every run of a launch is at the same slot), and the sampling families draw in whole
// Philox blocks so that the threads of a warp stay in step.

#if defined(__CUDACC__)
#define CAI_FN __device__ __forceinline__
#define CAI_METHOD __device__ __forceinline__
#define CAI_STATIC static __device__ __forceinline__
#define CAI_INF __longlong_as_double(0x7ff0000000000000LL)
#else
#include <math.h>
#define CAI_FN static inline
#define CAI_METHOD inline
#define CAI_STATIC static inline
#define CAI_INF HUGE_VAL
#endif

typedef unsigned int u32;
typedef unsigned long long u64;
typedef long long i64;
typedef signed char i8;

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

#define CAI_ALL_ARMS (~0ull >> (64 - KARMS))
#define CAI_HAS(mask, k) ((((mask) >> (k)) & 1ull) != 0ull)

#define CAI_PURPOSE_HIDDEN 0x48494444u
#define CAI_PURPOSE_POLICY 0x504f4c49u
#define CAI_INV53 (1.0 / 9007199254740992.0)

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

CAI_FN double cai_rsqrt(double x) {
#if defined(__CUDACC__)
    return rsqrt(x);
#else
    return 1.0 / sqrt(x);
#endif
}

// ------------------------------------------------------------------ Philox4x32-10

CAI_FN u32 cai_mulhi(u32 a, u32 b) {
#if defined(__CUDACC__)
    return __umulhi(a, b);
#else
    return (u32)(((u64)a * (u64)b) >> 32);
#endif
}

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

// A double in [0, 1) from two words (53 bits).
CAI_FN double cai_u53(u32 hi, u32 lo) {
    return (double)((((u64)hi << 32) | (u64)lo) >> 11) * CAI_INV53;
}

CAI_FN void cai_sincospi(double x, double* s, double* c) {
#if defined(__CUDACC__)
    sincospi(x, s, c);
#else
    *s = sin(3.14159265358979323846 * x);
    *c = cos(3.14159265358979323846 * x);
#endif
}

// The policy's stream of one run: uniforms two per Philox block, at position `pos` (in
// uniforms), and the spare normal of the last Box-Muller pair of cai_normal. A block is
// computed again for each uniform taken from it: no cache (six registers fewer, and no
// branch that threads out of step would take apart).
struct CaiRng {
    u32 k0, k1;
    u64 pos;
    int has_spare;
    double spare;
};

CAI_FN CaiWords cai_block_at(const CaiRng& g, u64 blk) {
    return cai_philox((u32)blk, (u32)(blk >> 32), CAI_PURPOSE_POLICY, 0u, g.k0, g.k1);
}

CAI_FN double cai_uniform(CaiRng& g) {
    CaiWords w = cai_block_at(g, g.pos >> 1);
    bool second = (g.pos & 1ull) != 0ull;
    g.pos += 1;
    return cai_u53(second ? w.w2 : w.w0, second ? w.w3 : w.w1);
}

// The next whole block of the stream (its two uniforms' worth of words), skipping the second
// uniform of a block already begun: every thread of a warp runs the same instructions, where
// the uniform-by-uniform path would have some threads compute a block while others use the
// one they hold (as soon as a rejected gamma draw or an exploration put them out of step).
CAI_FN CaiWords cai_block(CaiRng& g) {
    u64 blk = (g.pos + 1ull) >> 1;
    g.pos = (blk + 1ull) << 1;
    return cai_block_at(g, blk);
}

// A uniform integer in [0, high).
CAI_FN int cai_integer(CaiRng& g, int high) {
    int k = (int)(cai_uniform(g) * high);
    return k < high ? k : high - 1;
}

// Two independent standard normals from one block (Box-Muller).
CAI_FN void cai_normal2(const CaiWords& w, double* x1, double* x2) {
    double u1 = 1.0 - cai_u53(w.w0, w.w1);  // (0, 1]: the log is finite
    double u2 = cai_u53(w.w2, w.w3);
    double r = sqrt(-2.0 * log(u1));
    double s, c;
    cai_sincospi(2.0 * u2, &s, &c);
    *x1 = r * c;
    *x2 = r * s;
}

// Standard normal by Box-Muller; the second value of each pair waits in g.spare.
CAI_FN double cai_normal(CaiRng& g) {
    if (g.has_spare) {
        g.has_spare = 0;
        return g.spare;
    }
    double u1 = 1.0 - cai_uniform(g);
    double u2 = cai_uniform(g);
    double r = sqrt(-2.0 * log(u1));
    double s, c;
    cai_sincospi(2.0 * u2, &s, &c);
    g.spare = r * s;
    g.has_spare = 1;
    return r * c;
}

// Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang 2000), with d = shape - 1/3 and
// c = 1 / sqrt(9 d): one trial from the normal x and the uniform u, -1 when it is rejected.
CAI_FN double cai_gamma_try(double d, double c, double x, double u) {
    double v = 1.0 + c * x;
    if (v <= 0.0) return -1.0;
    v = v * v * v;
    double x2 = x * x;
    if (u < 1.0 - 0.0331 * x2 * x2) return d * v;
    if (log(u) < 0.5 * x2 + d * (1.0 - v + log(v))) return d * v;
    return -1.0;
}

// The same, trial after trial from the stream until one is accepted.
CAI_FN double cai_gamma(CaiRng& g, double d, double c) {
    while (true) {
        double x = cai_normal(g);
        double y = cai_gamma_try(d, c, x, cai_uniform(g));
        if (y >= 0.0) return y;
    }
}

// The gamma constants (d, c) of a shape.
struct CaiGammaDC {
    double d, c;
};

CAI_FN CaiGammaDC cai_gamma_dc(double shape) {
    CaiGammaDC out;
    out.d = shape - 1.0 / 3.0;
    out.c = cai_rsqrt(9.0 * out.d);
    return out;
}

// The lowest set bit of a nonzero mask.
CAI_FN int cai_lowest(u64 mask) {
#if defined(__CUDACC__)
    return __ffsll((long long)mask) - 1;
#else
    return __builtin_ctzll(mask);
#endif
}

// The gamma constants of both shapes of a Beta(a, b).
struct CaiBetaDC {
    CaiGammaDC a, b;
};

// A gamma trial's squeeze (Marsaglia and Tsang): v^3 of the trial, and *state 0 when the
// squeeze accepts it (the value is d v^3), 1 when only the log test can tell (then *rhs is
// 0.5 x^2 + d (1 - v^3): it accepts when log u < *rhs + d log v^3), 2 when it is rejected.
CAI_FN double cai_gamma_squeeze(double d, double c, double x, double u, double* rhs,
                                int* state) {
    double v = 1.0 + c * x;
    if (v <= 0.0) {
        *state = 2;
        *rhs = 0.0;
        return 0.0;
    }
    v = v * v * v;
    double x2 = x * x;
    *state = u < 1.0 - 0.0331 * x2 * x2 ? 0 : 1;
    *rhs = 0.5 * x2 + d * (1.0 - v);
    return v;
}

#ifndef CAI_LOG_BATCH
#define CAI_LOG_BATCH 0
#endif

// Beta(a_k, b_k) for every arm, as Ga / (Ga + Gb). Each gamma's first trial comes from two
// whole blocks per arm (two normals, two uniforms), so that every thread runs the same
// instructions; the rare rejected trials go on from the stream afterwards, one loop for all
// of them (one copy of the rejection loop in the code, not one per arm). CAI_LOG_BATCH=1:
// the squeeze's undecided trials (about one in ten) take their two logs in one loop after
// the arms too, so that a warp runs as many log tests as its busiest thread needs, not one
// for each gamma that any of its threads left undecided (benchmarks/bench_gpu.py times both).
template <class Arm>
CAI_FN void cai_betas(const Arm* arm, double* vals, CaiRng& g) {
    double ga[KARMS], gb[KARMS];
    u64 bad_a = 0, bad_b = 0;
#if CAI_LOG_BATCH
    double ua[KARMS], ub[KARMS], ra[KARMS], rb[KARMS];
    u64 log_a = 0, log_b = 0;
#endif
    CAI_FOR_ARMS(k) {
        CaiWords w = cai_block(g);
        CaiWords v = cai_block(g);
        double x1, x2;
        cai_normal2(w, &x1, &x2);
        double u1 = cai_u53(v.w0, v.w1), u2 = cai_u53(v.w2, v.w3);
#if CAI_LOG_BATCH
        int sa, sb;
        ga[k] = cai_gamma_squeeze(arm[k].a.d, arm[k].a.c, x1, u1, &ra[k], &sa);
        gb[k] = cai_gamma_squeeze(arm[k].b.d, arm[k].b.c, x2, u2, &rb[k], &sb);
        ua[k] = u1;
        ub[k] = u2;
        if (sa == 0) ga[k] *= arm[k].a.d;
        if (sb == 0) gb[k] *= arm[k].b.d;
        log_a |= (u64)(sa == 1) << k;
        log_b |= (u64)(sb == 1) << k;
        bad_a |= (u64)(sa == 2) << k;
        bad_b |= (u64)(sb == 2) << k;
#else
        ga[k] = cai_gamma_try(arm[k].a.d, arm[k].a.c, x1, u1);
        gb[k] = cai_gamma_try(arm[k].b.d, arm[k].b.c, x2, u2);
        bad_a |= (u64)(ga[k] < 0.0) << k;
        bad_b |= (u64)(gb[k] < 0.0) << k;
#endif
    }
#if CAI_LOG_BATCH
    while ((log_a | log_b) != 0ull) {
        bool is_a = log_a != 0ull;
        int k = cai_lowest(is_a ? log_a : log_b);
        if (is_a) log_a &= log_a - 1ull;
        else log_b &= log_b - 1ull;
        Arm dc = cai_get(arm, k);
        double d = is_a ? dc.a.d : dc.b.d;
        double v3 = is_a ? cai_get(ga, k) : cai_get(gb, k);
        double u = is_a ? cai_get(ua, k) : cai_get(ub, k);
        double rhs = is_a ? cai_get(ra, k) : cai_get(rb, k);
        bool ok = log(u) < rhs + d * log(v3);
        if (is_a) {
            cai_set(ga, k, d * v3);
            bad_a |= (u64)(!ok) << k;
        } else {
            cai_set(gb, k, d * v3);
            bad_b |= (u64)(!ok) << k;
        }
    }
#endif
    while ((bad_a | bad_b) != 0ull) {
        bool is_a = bad_a != 0ull;
        int k = cai_lowest(is_a ? bad_a : bad_b);
        if (is_a) bad_a &= bad_a - 1ull;
        else bad_b &= bad_b - 1ull;
        Arm dc = cai_get(arm, k);
        CaiGammaDC shape = is_a ? dc.a : dc.b;
        double y = cai_gamma(g, shape.d, shape.c);
        if (is_a) cai_set(ga, k, y);
        else cai_set(gb, k, y);
    }
    CAI_FOR_ARMS(k) vals[k] = ga[k] / (ga[k] + gb[k]);
}

// Index of the largest vals[k] over the arms in `mask` (its value in *top); ties uniformly at
// random (one uniform when several arms tie, none otherwise); -1 when the mask is empty.
CAI_FN int cai_argmax(const double* vals, u64 mask, CaiRng& g, double* top) {
    int best = -1;
    double bestv = -CAI_INF;
    int ties = 0;
    CAI_FOR_ARMS(k) {
        if (CAI_HAS(mask, k)) {
            double v = vals[k];
            if (best < 0 || v > bestv) {
                best = k;
                bestv = v;
                ties = 1;
            } else if (v == bestv) {
                ties += 1;
            }
        }
    }
    if (ties > 1) {
        int j = cai_integer(g, ties);  // the j-th tied arm, in arm order
        CAI_FOR_ARMS(k) {
            if (CAI_HAS(mask, k) && vals[k] == bestv) {
                if (j == 0) best = k;
                j -= 1;
            }
        }
    }
    *top = bestv;
    return best;
}

// ------------------------------------------------------------------ policy families
//
// A family is a struct (the CPU hooks' counterparts in corraoi/policies/builtin_hooks.py):
// Arm, what the family keeps per arm and recomputes only when the arm is played (set from its
// pulls n and successes s); St, its per-run state in registers (loaded from and stored to
// `ps`, the run's column of the state array, around each launch); forced() returns an arm to
// play whatever the score says, or -1; score() writes the index of every arm into vals (the
// candidate set is applied after); update() runs after the slot with the counts updated.

// What a family's functions see of the run at slot t: lt = ln t.
struct CaiSlot {
    i64 t;
    double lt;
};

struct CaiState {
    double* base;
    i64 stride;
    CAI_METHOD double& operator[](i64 i) const { return base[i * stride]; }
};

struct CaiNoArm {
    CAI_METHOD void set(i64, i64, const double*) {}
};

struct CaiNoState {
    CAI_METHOD void load(CaiState) {}
    CAI_METHOD void store(CaiState) const {}
};

#define CAI_FORCED_ARGS const CaiSlot &sl, const u32 *np, const double *prm, St &st, CaiRng &g
#define CAI_SCORE_ARGS                                                                        \
    const CaiSlot &sl, const u32 *np, const double *mu, const Arm *arm, double *vals,          \
        const double *prm, St &st, CaiRng &g
#define CAI_UPDATE_ARGS const CaiSlot &sl, int played, int rew, const double *prm, St &st, CaiState ps

CAI_FN int cai_first_unpulled(const u32* np) {
    int first = -1;
    CAI_FOR_ARMS(k) if (first < 0 && np[k] == 0) first = k;
    return first;
}

// Krishnasamy et al. (2021): explore w.p. min(1, 3 K ln^2 t / t), an arm uniformly at random.
CAI_FN int cai_explore(const CaiSlot& sl, CaiRng& g) {
    if (sl.t < 2) return -1;
    double prob = 3.0 * KARMS * sl.lt * sl.lt / (double)sl.t;
    if (cai_uniform(g) < prob) return cai_integer(g, KARMS);
    return -1;
}

// Beta(S + 1, F + 1) posteriors: the gamma constants of both shapes, per arm.
struct CaiBetaArm : CaiBetaDC {
    CAI_METHOD void set(i64 n, i64 s, const double*) {
        a = cai_gamma_dc((double)s + 1.0);
        b = cai_gamma_dc((double)(n - s) + 1.0);
    }
};

// UCB: each arm once, then argmax mu_hat + sqrt(c ln t / n_k).    params: c
struct UcbForm {
    struct Arm {
        double rsq;  // 1 / sqrt(n)
        CAI_METHOD void set(i64 n, i64, const double*) { rsq = cai_rsqrt((double)n); }
    };
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_first_unpulled(np); }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        double b = sqrt(prm[0] * sl.lt);
        CAI_FOR_ARMS(k) vals[k] = mu[k] + b * arm[k].rsq;
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Thompson sampling, Beta(S + 1, F + 1).
struct TsBetaForm {
    typedef CaiBetaArm Arm;
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_betas(arm, vals, g); }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Thompson sampling, N(mu_hat, beta / (n + 1)).                   params: beta
struct TsGaussForm {
    struct Arm {
        double sd;  // sqrt(beta / (n + 1))
        CAI_METHOD void set(i64 n, i64, const double* prm) { sd = sqrt(prm[0] / ((double)n + 1.0)); }
    };
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CAI_FOR_ARMS(k) {
            if (k % 2 == 0) {  // a block gives the normals of arms k and k + 1
                double x1, x2;
                cai_normal2(cai_block(g), &x1, &x2);
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
        double rsq2;  // 1 / sqrt(2 n)
        CAI_METHOD void set(i64 n, i64, const double*) { rsq2 = cai_rsqrt(2.0 * (double)n); }
    };
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) {
        int a = cai_explore(sl, g);
        return a >= 0 ? a : cai_first_unpulled(np);
    }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CAI_FOR_ARMS(k) vals[k] = mu[k] + sl.lt * arm[k].rsq2;  // sqrt(lt^2 / 2n), lt >= 0
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Q-TS: explore, else Beta(S + 1, F + 1) sampling.
struct QTsForm {
    typedef CaiBetaArm Arm;
    typedef CaiNoState St;
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_explore(sl, g); }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_betas(arm, vals, g); }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// Sliding-window UCB (Garivier and Moulines 2011).                params: window, c
// ps: [0, K) pulls in the window, [K, 2K) successes in the window (both in registers during
// a launch), then a ring of the last `window` slots: arm + 1 (0 = empty), then their rewards.
struct SwUcbForm {
    typedef CaiNoArm Arm;
    struct St {
        double n[KARMS], s[KARMS];
        CAI_METHOD void load(CaiState ps) {
            CAI_FOR_ARMS(k) {
                n[k] = ps[k];
                s[k] = ps[KARMS + k];
            }
        }
        CAI_METHOD void store(CaiState ps) const {
            CAI_FOR_ARMS(k) {
                ps[k] = n[k];
                ps[KARMS + k] = s[k];
            }
        }
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        i64 window = (i64)prm[0];
        double lt = sl.t > 1 ? (sl.t < window ? sl.lt : log((double)window)) : 0.0;
        double clt = prm[1] * lt;
        CAI_FOR_ARMS(k) {
            double n = st.n[k];
            vals[k] = n == 0.0 ? CAI_INF : st.s[k] / n + sqrt(clt / n);
        }
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        i64 window = (i64)prm[0];
        i64 pos = (sl.t - 1) % window;
        i64 ring_arm = 2 * KARMS + pos;
        i64 ring_rew = 2 * KARMS + window + pos;
        int old = (int)ps[ring_arm];
        double old_rew = ps[ring_rew];
        CAI_FOR_ARMS(k) {  // selects (as in cai_set): the arrays stay in registers
            st.n[k] = k == old - 1 ? st.n[k] - 1.0 : st.n[k];
            st.s[k] = k == old - 1 ? st.s[k] - old_rew : st.s[k];
            st.n[k] = k == played ? st.n[k] + 1.0 : st.n[k];
            st.s[k] = k == played ? st.s[k] + (double)rew : st.s[k];
        }
        ps[ring_arm] = played + 1.0;
        ps[ring_rew] = (double)rew;
    }
};

// Discounted Thompson sampling (Raj and Kalyani 2017).            params: gamma
// ps: [0, K) discounted successes, [K, 2K) discounted failures (in registers during a launch).
struct DTsForm {
    typedef CaiNoArm Arm;
    struct St {
        double s[KARMS], f[KARMS];
        CAI_METHOD void load(CaiState ps) {
            CAI_FOR_ARMS(k) {
                s[k] = ps[k];
                f[k] = ps[KARMS + k];
            }
        }
        CAI_METHOD void store(CaiState ps) const {
            CAI_FOR_ARMS(k) {
                ps[k] = s[k];
                ps[KARMS + k] = f[k];
            }
        }
    };
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        CaiBetaDC dc[KARMS];
        CAI_FOR_ARMS(k) {
            dc[k].a = cai_gamma_dc(st.s[k] + 1.0);
            dc[k].b = cai_gamma_dc(st.f[k] + 1.0);
        }
        cai_betas(dc, vals, g);
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        CAI_FOR_ARMS(k) {
            st.s[k] *= prm[0];
            st.f[k] *= prm[0];
            st.s[k] = k == played ? st.s[k] + (double)rew : st.s[k];
            st.f[k] = k == played ? st.f[k] + (1.0 - (double)rew) : st.f[k];
        }
    }
};

// ------------------------------------------------------------------ one run

// Arrays of per-run values are laid out [field][run] (`R` runs), so that the threads of a
// warp read and write neighbouring addresses. `lnt[j]` is ln(t0 + j + 1); `comb` is
// candidates.candidate_bitsets (K, 8) for the correlated forms.
#define CAI_PARAMS                                                                            \
    int R, u64 seed0, i64 t0, i64 nslots, const double *lnt, int n, int nrows, int kind,      \
        const double *cdf, const i64 *trace, const i8 *Y, const u64 *comb, int best,          \
        double mu_star, const double *prm, int S, i64 *pulls, i64 *succ, double *pstate,       \
        u64 *rpos, double *nspare, int *nhas, int *xprev, i64 *age_a, i64 *oage_a,             \
        i64 *reg_a, i64 *asum_a, int nck, const i64 *ck_t, double *ck_reg, double *ck_est,     \
        i64 *ck_pulls, int cap_run, i64 *cap
#define CAI_NAMES                                                                             \
    R, seed0, t0, nslots, lnt, n, nrows, kind, cdf, trace, Y, comb, best, mu_star, prm, S,     \
        pulls, succ, pstate, rpos, nspare, nhas, xprev, age_a, oage_a, reg_a, asum_a, nck,     \
        ck_t, ck_reg, ck_est, ck_pulls, cap_run, cap

// The per-slot capture of run `cap_run` (-1: none), CAI_CAPW values a slot of this launch into
// `cap`: the hidden state, the arm, the reward, the ages (own, oracle's), the regret and the
// AoI sum after the slot, the override flag and the candidate set as a bit mask (K <= 64).
// What `corraoi record --from` of a GPU sweep turns into the slots of one run.
#define CAI_CAPW 9

// The hidden state of slot t: one uniform from the (t, HIDDEN) block, inverted through the
// CDF of row 0 (X_1 and every X_t of an i.i.d. channel) or of row X_{t-1} + 1 (Markov).
CAI_FN int cai_hidden(int kind, const double* cdf, const i64* trace, int n, int nrows, int xp,
                      i64 t, u32 k0, u32 k1) {
    if (kind == 1) return (int)trace[t - 1];
    int row = (nrows > 1 && xp >= 0) ? xp + 1 : 0;
    CaiWords w = cai_philox((u32)t, (u32)((u64)t >> 32), CAI_PURPOSE_HIDDEN, 0u, k0, k1);
    double u = cai_u53(w.w0, w.w1);
    const double* c = cdf + (i64)row * n;
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (u < c[mid]) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

template <class P, int CORR, int AWARE>
CAI_FN void cai_run(int r, CAI_PARAMS) {
    typedef typename P::Arm Arm;
    typedef typename P::St St;
    u64 seed = seed0 + (u64)r;
    u32 k0 = (u32)seed, k1 = (u32)(seed >> 32);
    CaiRng g;
    g.k0 = k0;
    g.k1 = k1;
    g.pos = rpos[r];
    g.has_spare = nhas[r];
    g.spare = nspare[r];
    CaiState ps = {pstate + r, (i64)R};
    St st;
    st.load(ps);
    u32 np[KARMS], ns[KARMS];  // pulls and successes: at most T < 2^32 (limits.MAX_HORIZON)
    double mu[KARMS], fr[KARMS], vals[KARMS];
    Arm arm_of[KARMS];
    CAI_FOR_ARMS(k) {
        np[k] = (u32)pulls[(i64)k * R + r];
        ns[k] = (u32)succ[(i64)k * R + r];
        mu[k] = np[k] > 0 ? (double)ns[k] / (double)np[k] : 0.0;
        fr[k] = np[k] > 0 ? (double)(np[k] - ns[k]) / (double)np[k] : 0.0;
        arm_of[k].set(np[k], ns[k], prm);
    }
    i64 age = age_a[r], oage = oage_a[r], reg = reg_a[r], asum = asum_a[r];
    int xp = xprev[r];
    int ci = 0;
    while (ci < nck && ck_t[ci] <= t0) ++ci;
    i64 next_ck = ci < nck ? ck_t[ci] : -1;
    for (i64 j = 0; j < nslots; ++j) {
        CaiSlot sl;
        sl.t = t0 + j + 1;
        sl.lt = lnt[j];
        i64 t = sl.t;
        int x = cai_hidden(kind, cdf, trace, n, nrows, xp, t, k0, k1);
        xp = x;
        u64 cand = CAI_ALL_ARMS;
        int forced = P::forced(sl, np, prm, st, g);
        if (CORR && forced < 0) {
            // S_t: arms pulled at least (t - 1) / K times; k_emp the best of them; A_t the
            // arms whose pseudo-reward estimate against every pulled arm of S_t reaches
            // mu_hat[k_emp]: the arms a pulled l of S_t rules out are comb[l][code], code
            // saying which of 0, l's failure rate and l's success rate fall below the target
            u64 in_s = 0;
            CAI_FOR_ARMS(k) if ((i64)np[k] * KARMS >= t - 1) in_s |= 1ull << k;
            double target;
            int kemp = cai_argmax(mu, in_s, g, &target);
            u64 out = 0;
            CAI_FOR_ARMS(l) {
                if (CAI_HAS(in_s, l) && np[l] > 0) {
                    int code = (target > 0.0 ? 1 : 0) | (target > fr[l] ? 2 : 0) |
                               (target > mu[l] ? 4 : 0);
                    out |= comb[l * 8 + code];
                }
            }
            cand = (CAI_ALL_ARMS & ~out) | (1ull << kemp);
        }
        bool override_ = false;
        int arm;
        double top;
        if (AWARE) {
            double maxmu = 0.0;
            CAI_FOR_ARMS(k) maxmu = mu[k] > maxmu ? mu[k] : maxmu;
            override_ = maxmu > 0.0 && (double)age * maxmu > 1.0;
        }
        if (override_) {
            arm = cai_argmax(mu, CAI_ALL_ARMS, g, &top);
        } else if (forced >= 0) {
            arm = forced;
        } else {
            P::score(sl, np, mu, arm_of, vals, prm, st, g);
            arm = cai_argmax(vals, cand, g, &top);
        }
        int rew = Y[arm * n + x];
        {  // the played arm's values, recomputed for it alone
            u32 n1 = cai_get(np, arm) + 1u;
            u32 s1 = cai_get(ns, arm) + (u32)rew;
            double m1 = (double)s1 / (double)n1;
            double f1 = CORR ? (double)(n1 - s1) / (double)n1 : 0.0;
            Arm a1;
            a1.set(n1, s1, prm);
            cai_set(np, arm, n1);
            cai_set(ns, arm, s1);
            cai_set(mu, arm, m1);
            if (CORR) cai_set(fr, arm, f1);
            cai_set(arm_of, arm, a1);
        }
        P::update(sl, arm, rew, prm, st, ps);
        age = rew == 1 ? 1 : age + 1;
        oage = Y[best * n + x] == 1 ? 1 : oage + 1;
        reg += age - oage;
        asum += age;
        if (r == cap_run) {
            i64* row = cap + j * CAI_CAPW;
            row[0] = x;
            row[1] = arm;
            row[2] = rew;
            row[3] = age;
            row[4] = oage;
            row[5] = reg;
            row[6] = asum;
            row[7] = override_ ? 1 : 0;
            row[8] = (i64)cand;
        }
        if (t == next_ck) {
            ck_reg[(i64)ci * R + r] = (double)reg;
            ck_est[(i64)ci * R + r] = (double)asum - (double)t / mu_star;
            CAI_FOR_ARMS(k) ck_pulls[((i64)ci * KARMS + k) * R + r] = (i64)np[k];
            ++ci;
            next_ck = ci < nck ? ck_t[ci] : -1;
        }
    }
    CAI_FOR_ARMS(k) {
        pulls[(i64)k * R + r] = (i64)np[k];
        succ[(i64)k * R + r] = (i64)ns[k];
    }
    st.store(ps);
    age_a[r] = age;
    oage_a[r] = oage;
    reg_a[r] = reg;
    asum_a[r] = asum;
    xprev[r] = xp;
    rpos[r] = g.pos;
    nhas[r] = g.has_spare;
    nspare[r] = g.spare;
}

// ------------------------------------------------------------------ entry points
//
// advance_<family>_<c><a>: c = 1 for the correlated form, a = 1 for the AoI-aware one (each
// its own entry point, so that a form's registers are only what it uses).

#if defined(__CUDACC__)
#define CAI_ENTRY1(NAME, FORM, C, A)                                                          \
    extern "C" __global__ void advance_##NAME##_##C##A(CAI_PARAMS) {                          \
        int r = blockIdx.x * blockDim.x + threadIdx.x;                                        \
        if (r < R) cai_run<FORM, C, A>(r, CAI_NAMES);                                         \
    }
#else
#define CAI_ENTRY1(NAME, FORM, C, A)                                                          \
    extern "C" void advance_##NAME##_##C##A(CAI_PARAMS) {                                     \
        _Pragma("omp parallel for schedule(static)") for (int r = 0; r < R; ++r)              \
            cai_run<FORM, C, A>(r, CAI_NAMES);                                                \
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
