/* Q-Tree training kernel (paper Sect. 4.2): the one production episode loop
 * (qtree_task_planner/learning/training.py drives it in batches of episodes and calls back between them).
 *
 * Bit-identical to the reference episode (test/qtree_reference.py, the tests' oracle): CPython's MT19937 and random() (genrand_res53) on the state taken from
 * random.Random.getstate(), the same draws in the same order, the same double operations in the same order
 * (Eq. 7 update, Eq. 15 sum, Eq. 16 test; compiled without FMA contraction or fast-math). Used by
 * qtree_task_planner/learning/kernel.py through ctypes; the tree is exported to Python nodes on demand.
 *
 * Node i: mask (relocated obstacles), parent, action from the parent; per action a (0..n1-1, n1 = obstacles +
 * target): label (-1 unknown, 0 g_U, 1 g_O, 2 g_T, Eq. 11), Q, child (-1 none); the known edges in creation
 * order; the offered actions (ascending, pruned ones removed).
 * Training state between batches (kt_train calls): the RNG, the episode count, the Eq. 16 state and E_1st.
 * An episode whose oracle call fails is undone (journal of its steps): the tree, the counters and the RNG are
 * as at its start, so that a checkpoint taken then resumes exactly.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* ---- CPython's Mersenne Twister (Modules/_randommodule.c) ---- */
#define MT_N 624
#define MT_M 397
typedef struct { uint32_t mt[MT_N]; int index; } MT;

static uint32_t genrand_uint32(MT *s) {
    static const uint32_t mag01[2] = {0x0U, 0x9908b0dfU};
    uint32_t y, *mt = s->mt;
    if (s->index >= MT_N) {
        int kk;
        for (kk = 0; kk < MT_N - MT_M; kk++) {
            y = (mt[kk] & 0x80000000U) | (mt[kk + 1] & 0x7fffffffU);
            mt[kk] = mt[kk + MT_M] ^ (y >> 1) ^ mag01[y & 0x1U];
        }
        for (; kk < MT_N - 1; kk++) {
            y = (mt[kk] & 0x80000000U) | (mt[kk + 1] & 0x7fffffffU);
            mt[kk] = mt[kk + (MT_M - MT_N)] ^ (y >> 1) ^ mag01[y & 0x1U];
        }
        y = (mt[MT_N - 1] & 0x80000000U) | (mt[0] & 0x7fffffffU);
        mt[MT_N - 1] = mt[MT_M - 1] ^ (y >> 1) ^ mag01[y & 0x1U];
        s->index = 0;
    }
    y = mt[s->index++];
    y ^= (y >> 11);
    y ^= (y << 7) & 0x9d2c5680U;
    y ^= (y << 15) & 0xefc60000U;
    y ^= (y >> 18);
    return y;
}

static double rnd(MT *s) {
    uint32_t a = genrand_uint32(s) >> 5, b = genrand_uint32(s) >> 6;
    return (a * 67108864.0 + b) * (1.0 / 9007199254740992.0);
}

/* ---- tree ---- */
typedef int (*ask_fn)(uint64_t mask, int action);          /* label 0/1/2, or -1: the Python side raised */
typedef int (*path_fn)(int length, const int *actions);    /* 1 optimal, 0 not, -1: raised */

typedef struct {
    int n1, target, n_nodes, cap;
    double alpha, gamma;
    double *phi;
    uint64_t *mask;
    int32_t *parent, *action, *n_edges, *n_offer, *child;
    int8_t *label, *order, *offer;
    double *q;
    int64_t mp_q, memo_hits;
    double q_sum;
    /* memo: removed mask -> row of n1 labels (-1 unknown), open addressing */
    uint64_t *mkeys;
    int8_t *mrows;
    uint8_t *mused;
    int64_t mcap, mcount;
    /* training state kept between kt_train calls */
    MT rng;
    int ep, quiet, converged, e_1st, last_ok, last_len, last_steps, last_reached, yield_req;
    double prev_sum;
    int last[64];
    /* undo journal of the running episode: node, action, old Q, 0 known edge / 1 new edge / 2 new and pruned */
    int32_t *jnode, *ja;
    int8_t *jkind;
    double *jold;
    int jcap;
} KTree;

#if !defined(R_UNFEASIBLE) || !defined(R_TARGET)
#error "Eq. 13's rewards come from q_tree.py: kernel.py passes -DR_UNFEASIBLE and -DR_TARGET"
#endif

static int grow_nodes(KTree *t) {
    int cap = t->cap ? t->cap * 2 : 1024, n1 = t->n1;
#define GROW(ptr, type, per) do { type *p = realloc(t->ptr, sizeof(type) * (size_t)cap * (per)); \
        if (!p) return -1; t->ptr = p; } while (0)
    GROW(mask, uint64_t, 1); GROW(parent, int32_t, 1); GROW(action, int32_t, 1); GROW(n_edges, int32_t, 1);
    GROW(n_offer, int32_t, 1); GROW(child, int32_t, n1); GROW(label, int8_t, n1); GROW(order, int8_t, n1);
    GROW(offer, int8_t, n1); GROW(q, double, n1);
#undef GROW
    t->cap = cap;
    return 0;
}

static int new_node(KTree *t, uint64_t mask, int parent, int action) {
    if (t->n_nodes == t->cap && grow_nodes(t)) return -1;
    int i = t->n_nodes++, n1 = t->n1, k = 0;
    t->mask[i] = mask; t->parent[i] = parent; t->action[i] = action; t->n_edges[i] = 0;
    for (int a = 0; a < n1; a++) {
        t->child[(size_t)i * n1 + a] = -1;
        t->label[(size_t)i * n1 + a] = -1;
        t->q[(size_t)i * n1 + a] = 0.0;
        if (!((mask >> a) & 1)) t->offer[(size_t)i * n1 + k++] = (int8_t)a;
    }
    t->n_offer[i] = k;
    return i;
}

static uint64_t hash64(uint64_t x) {
    x ^= x >> 33; x *= 0xff51afd7ed558ccdULL; x ^= x >> 33; x *= 0xc4ceb9fe1a85ec53ULL; x ^= x >> 33;
    return x;
}

static int8_t *memo_row(KTree *t, uint64_t key) {
    if (2 * (t->mcount + 1) > t->mcap) {
        int64_t ocap = t->mcap, ncap = ocap ? ocap * 2 : 4096;
        uint64_t *k = calloc((size_t)ncap, sizeof(uint64_t));
        int8_t *r = malloc((size_t)ncap * t->n1);
        uint8_t *u = calloc((size_t)ncap, 1);
        if (!k || !r || !u) { free(k); free(r); free(u); return NULL; }
        for (int64_t j = 0; j < ocap; j++) {
            if (!t->mused[j]) continue;
            int64_t h = (int64_t)(hash64(t->mkeys[j]) & (uint64_t)(ncap - 1));
            while (u[h]) h = (h + 1) & (ncap - 1);
            u[h] = 1; k[h] = t->mkeys[j];
            memcpy(r + (size_t)h * t->n1, t->mrows + (size_t)j * t->n1, (size_t)t->n1);
        }
        free(t->mkeys); free(t->mrows); free(t->mused);
        t->mkeys = k; t->mrows = r; t->mused = u; t->mcap = ncap;
    }
    int64_t h = (int64_t)(hash64(key) & (uint64_t)(t->mcap - 1));
    while (t->mused[h]) {
        if (t->mkeys[h] == key) return t->mrows + (size_t)h * t->n1;
        h = (h + 1) & (t->mcap - 1);
    }
    t->mused[h] = 1; t->mkeys[h] = key; t->mcount++;
    memset(t->mrows + (size_t)h * t->n1, -1, (size_t)t->n1);
    return t->mrows + (size_t)h * t->n1;
}

KTree *kt_new(int n1, int target, double alpha, double gamma, const double *phi) {
    KTree *t = calloc(1, sizeof(KTree));
    if (!t) return NULL;
    t->n1 = n1; t->target = target; t->alpha = alpha; t->gamma = gamma; t->last_len = -2;
    t->phi = malloc(sizeof(double) * n1);
    if (!t->phi) { free(t); return NULL; }
    memcpy(t->phi, phi, sizeof(double) * n1);
    if (new_node(t, 0, -1, -1) < 0) return NULL;
    return t;
}

void kt_free(KTree *t) {
    if (!t) return;
    free(t->phi); free(t->mask); free(t->parent); free(t->action); free(t->n_edges); free(t->n_offer);
    free(t->child); free(t->label); free(t->order); free(t->offer); free(t->q);
    free(t->mkeys); free(t->mrows); free(t->mused);
    free(t->jnode); free(t->ja); free(t->jkind); free(t->jold);
    free(t);
}

/* max over the known feasible edges of node i (Eq. 7), 0 when none; Python: max(node.q.values()) */
static double max_q(const KTree *t, int i) {
    int n1 = t->n1, ne = t->n_edges[i], seen = 0;
    double m = 0.0;
    for (int k = 0; k < ne; k++) {
        int a = t->order[(size_t)i * n1 + k];
        if (t->label[(size_t)i * n1 + a] == 0) continue;
        double v = t->q[(size_t)i * n1 + a];
        if (!seen || v > m) { m = v; seen = 1; }
    }
    return m;
}

/* Journal one step of the running episode (capacity: i_max steps, reserved by kt_train). */
static void journal(KTree *t, int *jn, int node, int a, int kind, double old) {
    int k = (*jn)++;
    t->jnode[k] = node; t->ja[k] = a; t->jkind[k] = (int8_t)kind; t->jold[k] = old;
}

/* Undo the journalled steps, newest first (QTree.rollback): new edges forgotten (a pruned action offered again,
   in ascending place), old Q values back, the nodes created by the episode dropped. */
static void rollback(KTree *t, int jn, int n_nodes, int64_t mp_q, double q_sum) {
    int n1 = t->n1;
    for (int k = jn - 1; k >= 0; k--) {
        int node = t->jnode[k], a = t->ja[k];
        size_t e = (size_t)node * n1 + a;
        if (t->jkind[k] == 0) { t->q[e] = t->jold[k]; continue; }
        t->label[e] = -1; t->q[e] = 0.0; t->child[e] = -1;
        t->n_edges[node]--;
        if (t->jkind[k] == 2) {
            int8_t *off = t->offer + (size_t)node * n1;
            int n = t->n_offer[node], i = n;
            while (i > 0 && off[i - 1] > a) { off[i] = off[i - 1]; i--; }
            off[i] = (int8_t)a;
            t->n_offer[node] = n + 1;
        }
    }
    t->n_nodes = n_nodes; t->mp_q = mp_q; t->q_sum = q_sum;
}

/* One episode from s_H (the reference: test/qtree_reference.py). Returns steps, or -1 (ask raised; the
   episode is undone), -2 (out of memory). */
static int episode(KTree *t, int kind, int depth, int i_max, double eps, ask_fn ask, int *reached) {
    int node = 0, steps = 0, n1 = t->n1, target = t->target, jn = 0, n_nodes0 = t->n_nodes;
    int64_t mp_q0 = t->mp_q;
    double q_sum0 = t->q_sum;
    MT *rng = &t->rng, rng0 = t->rng;
    int best[64];
    *reached = 0;
    while (steps < i_max) {
        int8_t *off = t->offer + (size_t)node * n1;
        int n_off = t->n_offer[node], a;
        if (!n_off) break;
        if (kind == 0) {
            a = off[(int)(rnd(rng) * n_off)];
        } else if (off[n_off - 1] == target) {
            a = target;
        } else if (kind == 1 || rnd(rng) < eps) {
            a = off[(int)(rnd(rng) * n_off)];
        } else {
            double bv = 0.0;
            int nb = 0;
            for (int k = 0; k < n_off; k++) {
                int b = off[k];
                double v = t->label[(size_t)node * n1 + b] > 0 ? t->q[(size_t)node * n1 + b] : 0.0;
                if (nb == 0 || v > bv) { bv = v; best[0] = b; nb = 1; }
                else if (v == bv) best[nb++] = b;
            }
            a = nb == 1 ? best[0] : best[(int)(rnd(rng) * nb)];
        }
        steps++;
        size_t e = (size_t)node * n1 + a;
        int lab = t->label[e];
        if (lab < 0) {  /* new edge: one MP_q query */
            int8_t *row = memo_row(t, t->mask[node]);
            if (!row) return -2;
            if (row[a] < 0) {
                int l = ask(t->mask[node], a);
                if (l < 0) {
                    rollback(t, jn, n_nodes0, mp_q0, q_sum0);
                    t->rng = rng0;
                    return -1;
                }
                if (l & 4) t->yield_req = 1;  /* the caller's time for a callback has come */
                row[a] = (int8_t)(l & 3);
            } else {
                t->memo_hits++;
            }
            lab = row[a];
            t->label[e] = (int8_t)lab;
            t->order[(size_t)node * n1 + t->n_edges[node]++] = (int8_t)a;
            t->mp_q++;
            t->q[e] = 0.0;
            journal(t, &jn, node, a, lab == 0 ? 2 : 1, 0.0);
            if (lab == 0) {  /* prune: remove a from the offered list, keep ascending */
                int k = 0;
                while (off[k] != a) k++;
                memmove(off + k, off + k + 1, (size_t)(n_off - k - 1));
                t->n_offer[node]--;
            }
        } else {
            journal(t, &jn, node, a, 0, t->q[e]);
        }
        if (lab == 1) {
            int nxt = t->child[e];
            if (nxt < 0) {
                nxt = new_node(t, t->mask[node] | ((uint64_t)1 << a), node, a);
                if (nxt < 0) return -2;
                t->child[(size_t)node * n1 + a] = nxt;
            }
            double old = t->q[(size_t)node * n1 + a];
            double nw = old + t->alpha * ((-t->phi[a] + t->gamma * max_q(t, nxt)) - old);
            t->q[(size_t)node * n1 + a] = nw;
            t->q_sum += fabs(nw) - fabs(old);
            node = nxt;
        } else if (lab == 0) {
            double old = t->q[e];
            double nw = old + t->alpha * (R_UNFEASIBLE - old);
            t->q[e] = nw;
            t->q_sum += fabs(nw) - fabs(old);
            if (!depth) break;
        } else {
            double old = t->q[e];
            double nw = old + t->alpha * (R_TARGET - old);
            t->q[e] = nw;
            t->q_sum += fabs(nw) - fabs(old);
            *reached = 1;
            return steps;
        }
    }
    return steps;
}

/* QTree.best_path: highest feasible edge value from the root (ties: lowest index) to the target edge.
   Writes the actions to out (n1 entries), returns the length, or -1 when the path misses the target. */
int kt_best_path(const KTree *t, int *out) {
    int node = 0, n1 = t->n1, len = 0;
    for (int step = 0; step < n1; step++) {
        int ne = t->n_edges[node], best = -1;
        double bv = 0.0;
        for (int k = 0; k < ne; k++) {
            int a = t->order[(size_t)node * n1 + k];
            if (t->label[(size_t)node * n1 + a] == 0) continue;
            double v = t->q[(size_t)node * n1 + a];
            if (best < 0 || v > bv || (v == bv && a < best)) { bv = v; best = a; }
        }
        if (best < 0) return -1;
        out[len++] = best;
        if (best == t->target) return len;
        node = t->child[(size_t)node * n1 + best];
        if (node < 0) return -1;
    }
    return -1;
}

/* Episodes until `stop_at` episodes are done, Eq. 16 holds, or (after an episode) the ask callback asked for a
   yield (training.py's loop: its callbacks run between calls). eps, history: indexed by episode (E_max entries).
   Returns 0, -1 (a callback raised: after an ask, the episode is undone), -2 (out of memory). */
int kt_train(KTree *t, int kind, int depth, int i_max, int stop_at, const double *eps, double beta,
             int quiet_needed, int want_e1st, ask_fn ask, path_fn path_ok, double *history) {
    int path[64], reached;
    if (t->jcap < i_max) {
        int32_t *jnode = realloc(t->jnode, sizeof(int32_t) * (size_t)i_max);
        if (jnode) t->jnode = jnode;
        int32_t *ja = realloc(t->ja, sizeof(int32_t) * (size_t)i_max);
        if (ja) t->ja = ja;
        int8_t *jkind = realloc(t->jkind, (size_t)i_max);
        if (jkind) t->jkind = jkind;
        double *jold = realloc(t->jold, sizeof(double) * (size_t)i_max);
        if (jold) t->jold = jold;
        if (!jnode || !ja || !jkind || !jold) return -2;
        t->jcap = i_max;
    }
    t->yield_req = 0;
    while (t->ep < stop_at && !t->converged) {
        int steps = episode(t, kind, depth, i_max, eps[t->ep], ask, &reached);
        if (steps < 0) return steps;
        int ep = ++t->ep;
        t->last_steps = steps; t->last_reached = reached;
        double q_sum = t->q_sum;
        history[ep - 1] = q_sum;
        double delta = q_sum - t->prev_sum;
        t->prev_sum = q_sum;
        t->quiet = fabs(delta) <= beta ? t->quiet + 1 : 0;
        if (want_e1st && !t->e_1st) {
            int len = kt_best_path(t, path);
            /* Python compares the sequence with the last one; None == None (len -1 vs -1, or -2 first) */
            int same = (len == t->last_len) || (len == -1 && t->last_len == -2);
            if (same && len > 0) same = memcmp(path, t->last, sizeof(int) * (size_t)len) == 0;
            if (!same) {
                t->last_len = len;
                if (len > 0) memcpy(t->last, path, sizeof(int) * (size_t)len);
                if (len < 0) t->last_ok = 0;
                else {
                    t->last_ok = path_ok(len, path);
                    if (t->last_ok < 0) { t->last_ok = 0; return -1; }
                }
            }
            if (t->last_ok) t->e_1st = ep;
        }
        if (t->quiet >= quiet_needed) t->converged = 1;
        if (t->yield_req) break;
    }
    return 0;
}

/* The training state: RNG (CPython's state: 624 words and the index), episodes, Eq. 16 (prev_sum, quiet,
   converged), E_1st; the steps and the target flag of the last episode. */
void kt_set_state(KTree *t, const uint32_t *mt, int index, int ep, double prev_sum, int quiet, int converged,
                  int e_1st) {
    memcpy(t->rng.mt, mt, sizeof(t->rng.mt));
    t->rng.index = index;
    t->ep = ep; t->prev_sum = prev_sum; t->quiet = quiet; t->converged = converged; t->e_1st = e_1st;
    t->last_len = -2; t->last_ok = 0;
}

void kt_get_state(const KTree *t, uint32_t *mt, int *ints, double *prev_sum) {
    memcpy(mt, t->rng.mt, sizeof(t->rng.mt));
    ints[0] = t->rng.index; ints[1] = t->ep; ints[2] = t->quiet; ints[3] = t->converged; ints[4] = t->e_1st;
    ints[5] = t->last_steps; ints[6] = t->last_reached;
    *prev_sum = t->prev_sum;
}

/* Loading a stored tree (QTree.load_state, then node by node in allocation order): a node below `parent` by
   action a, an edge with its label and Q (child: the node an obstacle edge leads to), the counters. */
int kt_add_node(KTree *t, int parent, int a) {
    return new_node(t, t->mask[parent] | ((uint64_t)1 << a), parent, a);
}

void kt_add_edge(KTree *t, int node, int a, int label, double q, int child) {
    int n1 = t->n1;
    size_t e = (size_t)node * n1 + a;
    t->label[e] = (int8_t)label; t->q[e] = q; t->child[e] = child;
    t->order[(size_t)node * n1 + t->n_edges[node]++] = (int8_t)a;
    if (label == 0) {
        int8_t *off = t->offer + (size_t)node * n1;
        int n = t->n_offer[node], k = 0;
        while (k < n && off[k] != a) k++;
        if (k < n) { memmove(off + k, off + k + 1, (size_t)(n - k - 1)); t->n_offer[node]--; }
    }
}

void kt_set_counts(KTree *t, int64_t mp_q, double q_sum) { t->mp_q = mp_q; t->q_sum = q_sum; }

/* A certification turned the edge (removed set `mask`, action a) unfeasible (training.py): in every node with that
   removed set a known feasible edge a becomes unfeasible, as if first met so (Q = alpha * R_UNFEASIBLE, Eq. 7 from
   0; pruned from the offered actions); the subtree below it is dropped (its edges leave MP_q and Eq. 15's sum, the
   remaining nodes keep their creation order with compacted ids); the memo answers g_U from now on. Returns the
   edges relabelled, or -2 (out of memory). Between kt_train calls only (no episode running). */
int kt_relabel(KTree *t, uint64_t mask, int a) {
    int n1 = t->n1, n = t->n_nodes, count = 0, m = 0;
    int8_t *row = memo_row(t, mask);
    char *dead = calloc((size_t)n, 1);
    int32_t *remap = malloc(sizeof(int32_t) * (size_t)n);
    if (!row || !dead || !remap) { free(dead); free(remap); return -2; }
    row[a] = 0;
    for (int i = 0; i < n; i++) {
        size_t e = (size_t)i * n1 + a;
        if (t->mask[i] != mask || t->label[e] <= 0) continue;
        count++;
        if (t->child[e] >= 0) dead[t->child[e]] = 1;
        double nw = t->alpha * R_UNFEASIBLE;
        t->q_sum += fabs(nw) - fabs(t->q[e]);
        t->q[e] = nw; t->label[e] = 0; t->child[e] = -1;
        int8_t *off = t->offer + (size_t)i * n1;
        int no = t->n_offer[i], k = 0;
        while (k < no && off[k] != a) k++;
        if (k < no) { memmove(off + k, off + k + 1, (size_t)(no - k - 1)); t->n_offer[i]--; }
    }
    for (int i = 1; i < n; i++)  /* a child is created after its parent: one pass marks whole subtrees */
        if (!dead[i] && dead[t->parent[i]]) dead[i] = 1;
    for (int i = 0; i < n; i++) {
        if (!dead[i]) { remap[i] = m++; continue; }
        remap[i] = -1;
        for (int k = 0; k < t->n_edges[i]; k++) {
            t->q_sum -= fabs(t->q[(size_t)i * n1 + t->order[(size_t)i * n1 + k]]);
            t->mp_q--;
        }
    }
    for (int i = 0; i < n; i++) {
        int j = remap[i];
        if (j < 0) continue;
        size_t src = (size_t)i * n1, dst = (size_t)j * n1;
        t->mask[j] = t->mask[i]; t->action[j] = t->action[i];
        t->parent[j] = t->parent[i] >= 0 ? remap[t->parent[i]] : -1;
        t->n_edges[j] = t->n_edges[i]; t->n_offer[j] = t->n_offer[i];
        for (int b = 0; b < n1; b++) {
            int c = t->child[src + b];
            t->child[dst + b] = c >= 0 ? remap[c] : -1;
        }
        if (j != i) {
            memmove(t->label + dst, t->label + src, (size_t)n1);
            memmove(t->order + dst, t->order + src, (size_t)n1);
            memmove(t->offer + dst, t->offer + src, (size_t)n1);
            memmove(t->q + dst, t->q + src, sizeof(double) * (size_t)n1);
        }
    }
    t->n_nodes = m;
    t->last_len = -2; t->last_ok = 0;  /* E_1st: the greedy path is read again */
    free(dead); free(remap);
    return count;
}

/* accessors for the export to Python nodes */
int kt_n_nodes(const KTree *t) { return t->n_nodes; }
int64_t kt_mp_q(const KTree *t) { return t->mp_q; }
int64_t kt_memo_hits(const KTree *t) { return t->memo_hits; }
double kt_q_sum(const KTree *t) { return t->q_sum; }

/* Flat copies (n_nodes rows): parent, action, n_edges, n_offer; per action rows: order, label, q, child, offer. */
void kt_export(const KTree *t, int32_t *parent, int32_t *action, int32_t *n_edges, int32_t *n_offer,
               int8_t *order, int8_t *label, double *q, int32_t *child, int8_t *offer) {
    size_t n = (size_t)t->n_nodes, n1 = (size_t)t->n1;
    memcpy(parent, t->parent, n * sizeof(int32_t));
    memcpy(action, t->action, n * sizeof(int32_t));
    memcpy(n_edges, t->n_edges, n * sizeof(int32_t));
    memcpy(n_offer, t->n_offer, n * sizeof(int32_t));
    memcpy(order, t->order, n * n1);
    memcpy(label, t->label, n * n1);
    memcpy(q, t->q, n * n1 * sizeof(double));
    memcpy(child, t->child, n * n1 * sizeof(int32_t));
    memcpy(offer, t->offer, n * n1);
}
