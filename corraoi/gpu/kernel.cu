// corraoi's GPU kernels: one CUDA thread per run, every built-in policy family.
//
// CuPy compiles this file with NVRTC (corraoi/gpu/device.py); the same text also compiles as
// plain C++ (corraoi/gpu/emulate.py, a loop over runs instead of a thread grid), so that the
// policy logic is tested on machines without a GPU. Compile-time constant: KARMS (arms).
//
// Per run, per slot (the CPU kernel corraoi/engine/_kernel.py does the same in the same order):
// draw the hidden state from the run's hidden stream, compute the empirical means, let the
// policy force an arm, restrict to the correlated candidate set (when `correlated`), apply the
// AoI-aware override (when `aware`), else play the argmax of the policy's score over the
// candidates (ties uniformly at random); then update counts, ages and the policy's state.
//
// Random numbers: Philox4x32-10 (Salmon, Moraes, Dror, Shaw 2011), keyed by the run's 64-bit
// seed. The counter names the purpose: (slot, HIDDEN) draws the hidden state of a slot, so
// every policy sees the same path for a seed and nothing depends on the launch shape; the
// policy's draws come from (position, POLICY), a stream whose position is saved between
// launches. Counts and sums are 64-bit (AoI sums pass 2^31 near T = 1.3e9).

#if defined(__CUDACC__)
#define CAI_FN __device__ __forceinline__
#define CAI_STATIC static __device__ __forceinline__
#define CAI_INF __longlong_as_double(0x7ff0000000000000LL)
#else
#include <math.h>
#define CAI_FN static inline
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

#define CAI_PURPOSE_HIDDEN 0x48494444u
#define CAI_PURPOSE_POLICY 0x504f4c49u
#define CAI_INV53 (1.0 / 9007199254740992.0)

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
// uniforms), and the spare normal of the last Box-Muller pair.
struct CaiRng {
    u32 k0, k1;
    u64 pos;
    u64 blk;
    double d0, d1;
    int has_spare;
    double spare;
};

CAI_FN double cai_uniform(CaiRng& g) {
    u64 blk = g.pos >> 1;
    if (blk != g.blk) {
        CaiWords w = cai_philox((u32)blk, (u32)(blk >> 32), CAI_PURPOSE_POLICY, 0u, g.k0, g.k1);
        g.d0 = cai_u53(w.w0, w.w1);
        g.d1 = cai_u53(w.w2, w.w3);
        g.blk = blk;
    }
    double u = (g.pos & 1ull) ? g.d1 : g.d0;
    g.pos += 1;
    return u;
}

// A uniform integer in [0, high).
CAI_FN int cai_integer(CaiRng& g, int high) {
    int k = (int)(cai_uniform(g) * high);
    return k < high ? k : high - 1;
}

// Standard normal by Box-Muller; the second value of each pair waits in g.spare.
CAI_FN double cai_normal(CaiRng& g) {
    if (g.has_spare) {
        g.has_spare = 0;
        return g.spare;
    }
    double u1 = 1.0 - cai_uniform(g);  // (0, 1]: the log is finite
    double u2 = cai_uniform(g);
    double r = sqrt(-2.0 * log(u1));
    double s, c;
    cai_sincospi(2.0 * u2, &s, &c);
    g.spare = r * s;
    g.has_spare = 1;
    return r * c;
}

// Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang 2000).
CAI_FN double cai_gamma(CaiRng& g, double shape) {
    double d = shape - 1.0 / 3.0;
    double c = 1.0 / sqrt(9.0 * d);
    while (true) {
        double x = cai_normal(g);
        double v = 1.0 + c * x;
        if (v <= 0.0) continue;
        v = v * v * v;
        double u = cai_uniform(g);
        double x2 = x * x;
        if (u < 1.0 - 0.0331 * x2 * x2) return d * v;
        if (log(u) < 0.5 * x2 + d * (1.0 - v + log(v))) return d * v;
    }
}

CAI_FN double cai_beta(CaiRng& g, double a, double b) {
    double ga = cai_gamma(g, a);
    double gb = cai_gamma(g, b);
    return ga / (ga + gb);
}

// Index of the largest vals[k] with mask[k]; ties uniformly at random (one draw per extra
// tied arm, none without ties); -1 when the mask is empty.
CAI_FN int cai_argmax(const double* vals, const bool* mask, CaiRng& g) {
    int best = -1;
    double bestv = -CAI_INF;
    int ties = 0;
    for (int k = 0; k < KARMS; ++k) {
        if (!mask[k]) continue;
        double v = vals[k];
        if (best < 0 || v > bestv) {
            best = k;
            bestv = v;
            ties = 1;
        } else if (v == bestv) {
            ties += 1;
            if (cai_uniform(g) * ties < 1.0) best = k;
        }
    }
    return best;
}

// ------------------------------------------------------------------ policy families
//
// A family is a struct of three static functions (the CPU hooks' counterparts in
// corraoi/policies/builtin_hooks.py): forced() returns an arm to play whatever the score says,
// or -1; score() writes the index of every candidate arm into vals; update() runs after the
// slot with the counts already updated. `ps` is the run's own state (zero at the start).

struct CaiState {
    double* base;
    i64 stride;
#if defined(__CUDACC__)
    __device__ __forceinline__
#endif
    double& operator[](int i) const { return base[(i64)i * stride]; }
};

#define CAI_FORCED_ARGS i64 t, const i64 *np, const i64 *ns, const double *prm, CaiState ps, CaiRng &g
#define CAI_SCORE_ARGS                                                                        \
    i64 t, const i64 *np, const i64 *ns, const double *mu, const bool *cand, double *vals,    \
        const double *prm, CaiState ps, CaiRng &g
#define CAI_UPDATE_ARGS i64 t, int arm, int rew, const i64 *np, const i64 *ns, const double *prm, CaiState ps

CAI_FN int cai_first_unpulled(const i64* np) {
    for (int k = 0; k < KARMS; ++k)
        if (np[k] == 0) return k;
    return -1;
}

// Krishnasamy et al. (2021): explore w.p. min(1, 3 K ln^2 t / t), an arm uniformly at random.
CAI_FN int cai_explore(i64 t, CaiRng& g) {
    if (t < 2) return -1;
    double lt = log((double)t);
    double prob = 3.0 * KARMS * lt * lt / (double)t;
    if (cai_uniform(g) < prob) return cai_integer(g, KARMS);
    return -1;
}

CAI_FN void cai_ts_beta(const i64* np, const i64* ns, const bool* cand, double* vals, CaiRng& g) {
    for (int k = 0; k < KARMS; ++k)
        if (cand[k]) vals[k] = cai_beta(g, (double)ns[k] + 1.0, (double)(np[k] - ns[k]) + 1.0);
}

struct CaiNoUpdate {
    CAI_STATIC void update(CAI_UPDATE_ARGS) {}
};

// UCB: each arm once, then argmax mu_hat + sqrt(c ln t / n_k).    params: c
struct UcbForm : CaiNoUpdate {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_first_unpulled(np); }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        double clt = prm[0] * log((double)t);
        for (int k = 0; k < KARMS; ++k) vals[k] = mu[k] + sqrt(clt / (double)np[k]);
    }
};

// Thompson sampling, Beta(S + 1, F + 1).
struct TsBetaForm : CaiNoUpdate {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_ts_beta(np, ns, cand, vals, g); }
};

// Thompson sampling, N(mu_hat, beta / (n + 1)).                   params: beta
struct TsGaussForm : CaiNoUpdate {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        for (int k = 0; k < KARMS; ++k)
            if (cand[k]) vals[k] = mu[k] + sqrt(prm[0] / ((double)np[k] + 1.0)) * cai_normal(g);
    }
};

// Q-UCB: explore, else each arm once, then argmax mu_hat + sqrt(ln^2 t / (2 n_k)).
struct QUcbForm : CaiNoUpdate {
    CAI_STATIC int forced(CAI_FORCED_ARGS) {
        int arm = cai_explore(t, g);
        return arm >= 0 ? arm : cai_first_unpulled(np);
    }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        double lt = log((double)t);
        for (int k = 0; k < KARMS; ++k) vals[k] = mu[k] + sqrt(lt * lt / (2.0 * (double)np[k]));
    }
};

// Q-TS: explore, else Beta(S + 1, F + 1) sampling.
struct QTsForm : CaiNoUpdate {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return cai_explore(t, g); }
    CAI_STATIC void score(CAI_SCORE_ARGS) { cai_ts_beta(np, ns, cand, vals, g); }
};

// Sliding-window UCB (Garivier and Moulines 2011).                params: window, c
// ps: [0, K) pulls in the window, [K, 2K) successes in the window, then a ring of the last
// `window` slots: arm + 1 (0 = empty), then their rewards.
struct SwUcbForm {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        i64 window = (i64)prm[0];
        double lt = t > 1 ? log((double)(t < window ? t : window)) : 0.0;
        for (int k = 0; k < KARMS; ++k) {
            double n = ps[k];
            vals[k] = n == 0.0 ? CAI_INF : ps[KARMS + k] / n + sqrt(prm[1] * lt / n);
        }
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        i64 window = (i64)prm[0];
        int pos = (int)((t - 1) % window);
        int ring_arm = 2 * KARMS + pos;
        int ring_rew = 2 * KARMS + (int)window + pos;
        int old = (int)ps[ring_arm];
        if (old > 0) {
            ps[old - 1] -= 1.0;
            ps[KARMS + old - 1] -= ps[ring_rew];
        }
        ps[ring_arm] = arm + 1.0;
        ps[ring_rew] = (double)rew;
        ps[arm] += 1.0;
        ps[KARMS + arm] += (double)rew;
    }
};

// Discounted Thompson sampling (Raj and Kalyani 2017).            params: gamma
// ps: [0, K) discounted successes, [K, 2K) discounted failures.
struct DTsForm {
    CAI_STATIC int forced(CAI_FORCED_ARGS) { return -1; }
    CAI_STATIC void score(CAI_SCORE_ARGS) {
        for (int k = 0; k < KARMS; ++k)
            if (cand[k]) vals[k] = cai_beta(g, ps[k] + 1.0, ps[KARMS + k] + 1.0);
    }
    CAI_STATIC void update(CAI_UPDATE_ARGS) {
        for (int k = 0; k < 2 * KARMS; ++k) ps[k] *= prm[0];
        ps[arm] += (double)rew;
        ps[KARMS + arm] += 1.0 - (double)rew;
    }
};

// ------------------------------------------------------------------ one run

// Arrays of per-run values are laid out [field][run] (`R` runs), so that the threads of a
// warp read and write neighbouring addresses.
#define CAI_PARAMS                                                                            \
    int R, u64 seed0, i64 t0, i64 nslots, int n, int nrows, int kind, const double *cdf,      \
        const i64 *trace, const i8 *Y, const i8 *pclass, int best, double mu_star,             \
        int correlated, int aware, const double *prm, int S, i64 *pulls, i64 *succ,           \
        double *pstate, u64 *rpos, double *nspare, int *nhas, int *xprev, i64 *age_a,          \
        i64 *oage_a, i64 *reg_a, i64 *asum_a, int nck, const i64 *ck_t, double *ck_reg,        \
        double *ck_est, i64 *ck_pulls, int cap_run, i64 *cap
#define CAI_NAMES                                                                             \
    R, seed0, t0, nslots, n, nrows, kind, cdf, trace, Y, pclass, best, mu_star, correlated,   \
        aware, prm, S, pulls, succ, pstate, rpos, nspare, nhas, xprev, age_a, oage_a, reg_a,   \
        asum_a, nck, ck_t, ck_reg, ck_est, ck_pulls, cap_run, cap

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

template <class P>
CAI_FN void cai_run(int r, CAI_PARAMS) {
    u64 seed = seed0 + (u64)r;
    u32 k0 = (u32)seed, k1 = (u32)(seed >> 32);
    CaiRng g;
    g.k0 = k0;
    g.k1 = k1;
    g.pos = rpos[r];
    g.blk = ~0ull;
    g.d0 = g.d1 = 0.0;
    g.has_spare = nhas[r];
    g.spare = nspare[r];
    CaiState ps = {pstate + r, (i64)R};
    i64 np[KARMS], ns[KARMS];
    double mu[KARMS], vals[KARMS];
    bool cand[KARMS], in_s[KARMS];
    for (int k = 0; k < KARMS; ++k) {
        np[k] = pulls[(i64)k * R + r];
        ns[k] = succ[(i64)k * R + r];
        mu[k] = np[k] > 0 ? (double)ns[k] / (double)np[k] : 0.0;
    }
    i64 age = age_a[r], oage = oage_a[r], reg = reg_a[r], asum = asum_a[r];
    int xp = xprev[r];
    int ci = 0;
    while (ci < nck && ck_t[ci] <= t0) ++ci;
    for (i64 j = 0; j < nslots; ++j) {
        i64 t = t0 + j + 1;
        int x = cai_hidden(kind, cdf, trace, n, nrows, xp, t, k0, k1);
        xp = x;
        double maxmu = 0.0;  // mu[] holds the empirical means (only the played arm's changes)
        for (int k = 0; k < KARMS; ++k) {
            if (mu[k] > maxmu) maxmu = mu[k];
            cand[k] = true;
        }
        int forced = P::forced(t, np, ns, prm, ps, g);
        if (correlated && forced < 0) {
            // S_t: arms pulled at least (t - 1) / K times; k_emp the best of them; A_t the
            // arms whose pseudo-reward estimate against every pulled arm of S_t reaches
            // mu_hat[k_emp] (phi_hat is 0, l's failure rate, l's success rate or 1: pclass)
            for (int k = 0; k < KARMS; ++k) in_s[k] = np[k] * KARMS >= t - 1;
            int kemp = cai_argmax(mu, in_s, g);
            double target = mu[kemp];
            for (int k = 0; k < KARMS; ++k) {
                bool ok = true;
                for (int l = 0; l < KARMS; ++l) {
                    if (!in_s[l] || np[l] == 0) continue;
                    int c = pclass[k * KARMS + l];
                    if (c == 0) ok = target <= 0.0;
                    else if (c == 1) ok = (double)(np[l] - ns[l]) / (double)np[l] >= target;
                    else if (c == 2) ok = mu[l] >= target;
                    if (!ok) break;
                }
                cand[k] = ok;
            }
            cand[kemp] = true;
        }
        bool override_ = aware && maxmu > 0.0 && (double)age * maxmu > 1.0;
        int arm;
        if (override_) {
            for (int k = 0; k < KARMS; ++k) in_s[k] = true;
            arm = cai_argmax(mu, in_s, g);
        } else if (forced >= 0) {
            arm = forced;
        } else {
            P::score(t, np, ns, mu, cand, vals, prm, ps, g);
            arm = cai_argmax(vals, cand, g);
        }
        int rew = Y[arm * n + x];
        np[arm] += 1;
        ns[arm] += rew;
        mu[arm] = (double)ns[arm] / (double)np[arm];
        P::update(t, arm, rew, np, ns, prm, ps);
        age = rew == 1 ? 1 : age + 1;
        oage = Y[best * n + x] == 1 ? 1 : oage + 1;
        reg += age - oage;
        asum += age;
        if (r == cap_run) {
            i64* row = cap + j * CAI_CAPW;
            u64 mask = 0;
            for (int k = 0; k < KARMS; ++k) mask |= (u64)cand[k] << k;
            row[0] = x;
            row[1] = arm;
            row[2] = rew;
            row[3] = age;
            row[4] = oage;
            row[5] = reg;
            row[6] = asum;
            row[7] = override_ ? 1 : 0;
            row[8] = (i64)mask;
        }
        if (ci < nck && ck_t[ci] == t) {
            ck_reg[(i64)ci * R + r] = (double)reg;
            ck_est[(i64)ci * R + r] = (double)asum - (double)t / mu_star;
            for (int k = 0; k < KARMS; ++k) ck_pulls[((i64)ci * KARMS + k) * R + r] = np[k];
            ++ci;
        }
    }
    for (int k = 0; k < KARMS; ++k) {
        pulls[(i64)k * R + r] = np[k];
        succ[(i64)k * R + r] = ns[k];
    }
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

#if defined(__CUDACC__)
#define CAI_ENTRY(NAME, FORM)                                                                 \
    extern "C" __global__ void advance_##NAME(CAI_PARAMS) {                                   \
        int r = blockIdx.x * blockDim.x + threadIdx.x;                                        \
        if (r < R) cai_run<FORM>(r, CAI_NAMES);                                               \
    }
#else
#define CAI_ENTRY(NAME, FORM)                                                                 \
    extern "C" void advance_##NAME(CAI_PARAMS) {                                              \
        _Pragma("omp parallel for schedule(static)") for (int r = 0; r < R; ++r)              \
            cai_run<FORM>(r, CAI_NAMES);                                                      \
    }
#endif

CAI_ENTRY(ucb, UcbForm)
CAI_ENTRY(ts_beta, TsBetaForm)
CAI_ENTRY(ts_gauss, TsGaussForm)
CAI_ENTRY(q_ucb, QUcbForm)
CAI_ENTRY(q_ts, QTsForm)
CAI_ENTRY(sw_ucb, SwUcbForm)
CAI_ENTRY(d_ts, DTsForm)

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
