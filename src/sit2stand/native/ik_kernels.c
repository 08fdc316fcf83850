/* sit2stand's compiled kernels for the per-frame COM-hard IK (sit2stand.retarget.ik): the markers' least-squares
 * terms, the feet's equality rows and the step's QP. Plain C99, no dependency beyond libm; loaded with ctypes
 * (sit2stand.native), each taking its arrays as one block of pointers.
 *
 * Layouts: matrices row-major unless a stride says otherwise; indices are C ints (int32). Units SI, world frame.
 */
#include <math.h>
#include <string.h>

/* The entry points are compiled twice on x86-64, for the baseline and for x86-64-v3 (AVX2, FMA), and the loader
 * picks the one the CPU runs (GCC's and Clang's function multiversioning): the cache may be shared by hosts of
 * different CPUs, and at these sizes the wider units take a third off the QP. Helpers are inlined into each. */
#if defined(__x86_64__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define CLONED __attribute__((target_clones("arch=x86-64-v3", "default")))
#endif
#endif
#ifndef CLONED
#define CLONED
#endif
#define HELPER static inline __attribute__((always_inline))

/* The markers' Gauss-Newton terms.
 *
 *   P_k   = R_j o_k + t_j                                   (marker k on joint j: world position [m])
 *   J_k   = (v_i + omega_i x P_k)  for the dofs i that move joint j, 0 elsewhere   (world linear Jacobian)
 *   H    += w_k J_k' J_k,   g += w_k J_k' (P_k - target_k)
 *
 * J: the joints' world Jacobians (Pinocchio's data.J after computeJointJacobians), 6 x nv, element (r, c) at
 * J[r * j_row + c * j_col]. oMi: the joints' world placements as Pinocchio's data.oMi holds them, 12 doubles per
 * joint (rotation column-major, then translation). joint_id: each marker's joint in oMi; joint_row: its row in
 * dof_start / dof_count, whose run of `dofs` lists the tangent indices that move that joint.
 * H (nv x nv) and g (nv) are overwritten: H = diag + sum_k w_k J_k' J_k. P (m x 3) receives the positions.
 * fixed: J, oMi, weight (m), target (m x 3), diag (nv), P, work (3 nv); layout: joint_id, joint_row, offset
 * (m x 3), dofs, dof_start, dof_count; out: H, g. */
HELPER void markers_(int nv, int m, int j_row, int j_col, void *const *fixed, void *const *layout,
                     void *const *out)
{
    const double *J = fixed[0], *oMi = fixed[1], *weight = fixed[2], *target = fixed[3], *diag = fixed[4];
    double *P = fixed[5], *work = fixed[6], *H = out[0], *g = out[1];       /* work: 3 nv */
    const int *joint_id = layout[0], *joint_row = layout[1], *dofs = layout[3], *dof_start = layout[4],
              *dof_count = layout[5];
    const double *offset = layout[2];
    memset(H, 0, sizeof(double) * nv * nv);
    memset(g, 0, sizeof(double) * nv);
    for (int k = 0; k < m; ++k) {
        const double *R = oMi + 12 * joint_id[k], *t = R + 9, *o = offset + 3 * k;
        double *p = P + 3 * k;
        for (int r = 0; r < 3; ++r)
            p[r] = R[r] * o[0] + R[r + 3] * o[1] + R[r + 6] * o[2] + t[r];
        const int *idx = dofs + dof_start[joint_row[k]];
        const int n = dof_count[joint_row[k]];
        double *jx = work, *jy = work + nv, *jz = work + 2 * nv;
        for (int a = 0; a < n; ++a) {
            const int c = idx[a];
            const double vx = J[c * j_col], vy = J[j_row + c * j_col], vz = J[2 * j_row + c * j_col];
            const double wx = J[3 * j_row + c * j_col], wy = J[4 * j_row + c * j_col], wz = J[5 * j_row + c * j_col];
            jx[a] = vx + wy * p[2] - wz * p[1];
            jy[a] = vy + wz * p[0] - wx * p[2];
            jz[a] = vz + wx * p[1] - wy * p[0];
        }
        const double w = weight[k];
        const double ex = w * (p[0] - target[3 * k]), ey = w * (p[1] - target[3 * k + 1]),
                     ez = w * (p[2] - target[3 * k + 2]);
        for (int a = 0; a < n; ++a) {
            const int ca = idx[a];
            const double ax = w * jx[a], ay = w * jy[a], az = w * jz[a];
            g[ca] += jx[a] * ex + jy[a] * ey + jz[a] * ez;
            double *row = H + (size_t)ca * nv;
            for (int b = 0; b < n; ++b)
                row[idx[b]] += ax * jx[b] + ay * jy[b] + az * jz[b];
        }
    }
    for (int i = 0; i < nv; ++i)
        H[(size_t)i * nv + i] += diag[i];
}

CLONED void marker_terms(int nv, int m, int j_row, int j_col, void *const *fixed, void *const *layout,
                         void *const *out)
{
    markers_(nv, m, j_row, j_col, fixed, layout, out);
}

/* x . y over n entries; the reduction's order is free (-fopenmp-simd), so it runs in SIMD lanes. */
HELPER double dot(int n, const double *x, const double *y)
{
    double s = 0.0;
#pragma omp simd reduction(+ : s)
    for (int k = 0; k < n; ++k)
        s += x[k] * y[k];
    return s;
}

/* y += alpha x over n entries. */
HELPER void axpy(int n, double alpha, const double *x, double *y)
{
#pragma omp simd
    for (int k = 0; k < n; ++k)
        y[k] += alpha * x[k];
}

/* In-place Cholesky U' U of the n x n matrix at a (row stride lda; its upper triangle read and overwritten by U,
 * row-major, so that every inner loop runs along a row), and the reciprocals of U's diagonal in inv (n): the
 * solves multiply by them. 0 if not positive definite. */
HELPER int cholesky(int n, double *a, int lda, double *inv)
{
    for (int j = 0; j < n; ++j) {
        double *uj = a + (size_t)j * lda;
        if (!(uj[j] > 0.0))
            return 0;
        uj[j] = sqrt(uj[j]);
        inv[j] = 1.0 / uj[j];
        for (int k = j + 1; k < n; ++k)
            uj[k] *= inv[j];
        for (int i = j + 1; i < n; ++i)        /* the trailing block, row by row: a_ik -= u_ji u_jk, k >= i */
            axpy(n - i, -uj[i], uj + i, a + (size_t)i * lda + i);
    }
    return 1;
}

/* Solve U' Y = Y in place for nr right-hand sides at once: Y (n x nr, row stride ldy), each row one unknown. */
HELPER void forward(int n, int nr, const double *U, int lda, const double *inv, double *Y, int ldy)
{
    for (int k = 0; k < n; ++k) {
        double *yk = Y + (size_t)k * ldy;
        for (int r = 0; r < nr; ++r)
            yk[r] *= inv[k];
        const double *uk = U + (size_t)k * lda;
        for (int i = k + 1; i < n; ++i)
            axpy(nr, -uk[i], yk, Y + (size_t)i * ldy);
    }
}

/* Solve U x = b in place (one right-hand side). */
HELPER void backward(int n, const double *U, int lda, const double *inv, double *b)
{
    for (int i = n - 1; i >= 0; --i) {
        const double *ui = U + (size_t)i * lda;
        b[i] = (b[i] - dot(n - 1 - i, ui + i + 1, b + i + 1)) * inv[i];
    }
}

/* One equality-constrained solve on a working set: the bounds in `bound` (-1 at lo, +1 at hi, 0 free) fixed, the
 * rows of E (ne x n: A, then the active inequality rows) held at e. x (n) and lam (ne) out; 0 if the reduced
 * Hessian or the rows' Schur complement is singular. With H_FF = U'U, Y = U'^-1 E_F', z = U'^-1 r:
 * (Y'Y) lam = e - E_W x_W + Y'z, x_F = U^-1 (Y lam - z). */
HELPER int working_set_solve(int n, int ne, const double *H, const double *g, const double *E, const double *e,
                             const double *lo, const double *hi, const int *bound, double *x, double *lam,
                             double *work)
{
    int *free_ = (int *)work, *fixed = free_ + n;      /* n ints each, in the room of n doubles */
    int nf = 0, nw = 0;
    for (int i = 0; i < n; ++i) {
        if (bound[i] == 0) {
            free_[nf++] = i;
        } else {
            fixed[nw++] = i;
            x[i] = bound[i] < 0 ? lo[i] : hi[i];
        }
    }
    double *U = work + n;           /* nf x nf */
    double *Y = U + (size_t)n * n;  /* nf x ne */
    double *z = Y + (size_t)ne * n; /* nf */
    double *S = z + n;              /* ne x ne */
    double *inv_u = S + (size_t)ne * ne, *inv_s = inv_u + n;
    for (int a = 0; a < nf; ++a) {
        const double *h = H + (size_t)free_[a] * n;
        double r = g[free_[a]];
        for (int k = 0; k < nw; ++k)
            r += h[fixed[k]] * x[fixed[k]];
        z[a] = r;
        for (int b = a; b < nf; ++b)
            U[(size_t)a * nf + b] = h[free_[b]];
        for (int q = 0; q < ne; ++q)
            Y[(size_t)a * ne + q] = E[(size_t)q * n + free_[a]];
    }
    for (int q = 0; q < ne; ++q) {
        const double *eq = E + (size_t)q * n;
        double s = e[q];
        for (int k = 0; k < nw; ++k)
            s -= eq[fixed[k]] * x[fixed[k]];
        lam[q] = s;
    }
    if (!cholesky(nf, U, nf, inv_u))
        return 0;
    forward(nf, 1, U, nf, inv_u, z, 1);
    forward(nf, ne, U, nf, inv_u, Y, ne);
    memset(S, 0, sizeof(double) * ne * ne);
    for (int a = 0; a < nf; ++a) {               /* S = Y'Y (upper triangle), lam += Y'z */
        const double *ya = Y + (size_t)a * ne;
        for (int q = 0; q < ne; ++q)
            axpy(ne - q, ya[q], ya + q, S + (size_t)q * ne + q);
        axpy(ne, z[a], ya, lam);
    }
    if (!cholesky(ne, S, ne, inv_s))
        return 0;
    forward(ne, 1, S, ne, inv_s, lam, 1);
    backward(ne, S, ne, inv_s, lam);
    for (int a = 0; a < nf; ++a)
        z[a] = dot(ne, Y + (size_t)a * ne, lam) - z[a];
    backward(nf, U, nf, inv_u, z);
    for (int a = 0; a < nf; ++a)
        x[free_[a]] = z[a];
    return 1;
}

/* min 1/2 x'Hx + g'x  s.t.  A x = b (me rows),  C x >= d (mi rows),  lo <= x <= hi, by a primal-dual active set
 * (Hintermueller, Ito, Kunisch, SIAM J. Optim. 2002) started from the working set in `bound` (n: -1 at lo, +1 at
 * hi, 0 free) and `row` (mi: 1 active); both are updated. Returns the iterations it took, or 0 when it did not find
 * a point meeting the KKT conditions within max_iter (the caller falls back to a general solver): the answer it
 * returns is then exact, x feasible within tol and the multipliers' signs right.
 * lam (n + me + mi) receives the multipliers in DAQP's convention: H x + g + lam[:n] + [A; C]' lam[n:] = 0.
 * p: H, g, A, b, C, d, lo, hi, x, lam, bound, row, E ((me + mi) x n), work (5 n + n n + (me + mi) (n + me + mi
 * + 4) doubles). */
CLONED int box_qp(int n, int me, int mi, int max_iter, double tol, void *const *p)
{
    const double *H = p[0], *g = p[1], *A = p[2], *b = p[3], *C = p[4], *d = p[5], *lo = p[6], *hi = p[7];
    double *x = p[8], *lam = p[9], *E = p[12], *work = p[13];
    int *bound = p[10], *row = p[11];
    const int mmax = me + mi;
    double *e = work;
    double *mu = e + mmax;
    double *inner = mu + mmax;
    for (int i = 0; i < n; ++i)        /* a start's bound or row that is infinite now (a joint on its stop) */
        if ((bound[i] < 0 && !isfinite(lo[i])) || (bound[i] > 0 && !isfinite(hi[i])))
            bound[i] = 0;
    for (int j = 0; j < mi; ++j)
        if (row[j] && !isfinite(d[j]))
            row[j] = 0;
    for (int it = 1; it <= max_iter; ++it) {
        int ne = me;
        memcpy(E, A, sizeof(double) * me * n);
        memcpy(e, b, sizeof(double) * me);
        for (int j = 0; j < mi; ++j)
            if (row[j]) {
                memcpy(E + (size_t)ne * n, C + (size_t)j * n, sizeof(double) * n);
                e[ne++] = d[j];
            }
        if (!working_set_solve(n, ne, H, g, E, e, lo, hi, bound, x, mu, inner))
            return 0;
        int changed = 0;
        /* bounds: the gradient left after the rows' forces is the bound's force */
        for (int i = 0; i < n; ++i) {
            double r = g[i] + dot(n, H + (size_t)i * n, x);
            for (int q = 0; q < ne; ++q)
                r -= E[(size_t)q * n + i] * mu[q];
            lam[i] = bound[i] == 0 ? 0.0 : -r;
            if (bound[i] == 0) {
                if (x[i] < lo[i] - tol) { bound[i] = -1; changed = 1; }
                else if (x[i] > hi[i] + tol) { bound[i] = 1; changed = 1; }
            } else if ((bound[i] < 0 && r < -tol) || (bound[i] > 0 && r > tol)) {
                bound[i] = 0;
                changed = 1;
            }
        }
        for (int q = 0; q < me; ++q)
            lam[n + q] = -mu[q];
        for (int j = 0, q = me; j < mi; ++j) {
            if (row[j]) {
                lam[n + me + j] = -mu[q];
                if (mu[q++] < -tol) { row[j] = 0; changed = 1; }
            } else {
                lam[n + me + j] = 0.0;
                if (dot(n, C + (size_t)j * n, x) - d[j] < -tol) { row[j] = 1; changed = 1; }
            }
        }
        if (!changed)
            return it;
    }
    return 0;
}

/* log of a rotation (3 x 3, row-major) as a rotation vector w [rad]; 0 when the angle is too close to pi for the
 * formula's accuracy (the caller then asks Pinocchio). */
HELPER int log3(const double *R, double *w, double *theta_out)
{
    const double c = 0.5 * (R[0] + R[4] + R[8] - 1.0);
    if (c < -0.99)
        return 0;
    const double theta = acos(c > 1.0 ? 1.0 : c);
    const double s = sin(theta);
    const double k = theta < 1e-6 ? 0.5 + theta * theta / 12.0 : 0.5 * theta / s;   /* theta / (2 sin theta) */
    w[0] = k * (R[7] - R[5]);
    w[1] = k * (R[2] - R[6]);
    w[2] = k * (R[3] - R[1]);
    *theta_out = theta;
    return 1;
}

/* The feet's equality rows: for each of `count` frames (a sole), its 6 rows of the LOCAL frame Jacobian
 * (linear, angular) into A (count * 6 x nv, row-major) and -log6(target^-1 X) into b (count * 6), where X is the
 * frame's world placement: joint_id's placement in oMi (Pinocchio's layout, see marker_terms) times `placement`
 * (a 4 x 4 homogeneous matrix per frame, row-major), and `target` the same layout. Returns 0 if a rotation error
 * is too close to pi.
 * p: J, oMi, joint_id, placement, target, and the frames' joint_row, dofs, dof_start, dof_count as a point set
 * lays them out (see marker_terms); out: A, b (its first 6 count rows). */
HELPER int soles_(int nv, int count, int j_row, int j_col, void *const *p, void *const *out)
{
    const double *J = p[0], *oMi = p[1], *placement = p[3], *target = p[4];
    const int *joint_id = p[2], *joint_row = p[5], *dofs = p[6], *dof_start = p[7], *dof_count = p[8];
    double *A = out[0], *b = out[1];
    memset(A, 0, sizeof(double) * 6 * count * nv);
    for (int f = 0; f < count; ++f) {
        const double *Ri = oMi + 12 * joint_id[f], *ti = Ri + 9;       /* column-major rotation */
        const double *Mf = placement + 16 * f, *Mt = target + 16 * f;  /* homogeneous, row-major */
        double R[9], p[3], Re[9], pe[3], d[3];
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c)
                R[3 * r + c] = Ri[r] * Mf[c] + Ri[r + 3] * Mf[4 + c] + Ri[r + 6] * Mf[8 + c];
            p[r] = Ri[r] * Mf[3] + Ri[r + 3] * Mf[7] + Ri[r + 6] * Mf[11] + ti[r];
            d[r] = p[r] - Mt[4 * r + 3];
        }
        for (int r = 0; r < 3; ++r) {                                  /* target^-1 X */
            for (int c = 0; c < 3; ++c)
                Re[3 * r + c] = Mt[r] * R[c] + Mt[4 + r] * R[3 + c] + Mt[8 + r] * R[6 + c];
            pe[r] = Mt[r] * d[0] + Mt[4 + r] * d[1] + Mt[8 + r] * d[2];
        }
        double w[3], theta;
        if (!log3(Re, w, &theta))
            return 0;
        /* v = V^-1 pe,  V^-1 = I - [w]x / 2 + a [w]x^2,  a = (1 - theta sin / (2 (1 - cos))) / theta^2 */
        const double a = theta < 1e-4 ? 1.0 / 12.0 + theta * theta / 720.0 :
                         (1.0 - theta * sin(theta) / (2.0 * (1.0 - cos(theta)))) / (theta * theta);
        double wx[3], wxx[3];
        wx[0] = w[1] * pe[2] - w[2] * pe[1];
        wx[1] = w[2] * pe[0] - w[0] * pe[2];
        wx[2] = w[0] * pe[1] - w[1] * pe[0];
        wxx[0] = w[1] * wx[2] - w[2] * wx[1];
        wxx[1] = w[2] * wx[0] - w[0] * wx[2];
        wxx[2] = w[0] * wx[1] - w[1] * wx[0];
        double *bf = b + 6 * f;
        for (int r = 0; r < 3; ++r) {
            bf[r] = -(pe[r] - 0.5 * wx[r] + a * wxx[r]);
            bf[3 + r] = -w[r];
        }
        const int *idx = dofs + dof_start[joint_row[f]];
        double *Af = A + (size_t)6 * f * nv;
        for (int k = 0; k < dof_count[joint_row[f]]; ++k) {
            const int c = idx[k];
            const double vx = J[c * j_col], vy = J[j_row + c * j_col], vz = J[2 * j_row + c * j_col];
            const double ox = J[3 * j_row + c * j_col], oy = J[4 * j_row + c * j_col], oz = J[5 * j_row + c * j_col];
            const double lv[3] = {vx + oy * p[2] - oz * p[1], vy + oz * p[0] - ox * p[2], vz + ox * p[1] - oy * p[0]};
            const double lw[3] = {ox, oy, oz};
            for (int r = 0; r < 3; ++r) {                              /* R' (world) */
                Af[(size_t)r * nv + c] = R[r] * lv[0] + R[3 + r] * lv[1] + R[6 + r] * lv[2];
                Af[(size_t)(3 + r) * nv + c] = R[r] * lw[0] + R[3 + r] * lw[1] + R[6 + r] * lw[2];
            }
        }
    }
    return 1;
}

CLONED int sole_rows(int nv, int count, int j_row, int j_col, void *const *p, void *const *out)
{
    return soles_(nv, count, j_row, j_col, p, out);
}

/* A whole Gauss-Newton step's QP terms but for the rules a caller adds, in one call, after computeJointJacobians
 * and jacobianCenterOfMass on the data: the markers' terms into H and g (marker_terms), the feet's rows into the
 * first 6 count rows of A and b (sole_rows), then
 *   g[i] += mu[i] (q[i + 1] - q_ref[i + 1]), i >= 6        the posture prior (1-DoF joints; mu is 0 on the base)
 *   A[r0 + a] = Jcom[axis_a], b[r0 + a] = c_target[axis_a] - com[axis_a]          the COM's rows, a < n_axes
 *   lo[i] = -free, hi[i] = free, i < 6                     the base's step is free
 *   lo[6 + j] = min(q_lo[j] - q[7 + j], 0), hi[6 + j] = max(q_hi[j] - q[7 + j], 0)   the joints' box; a joint
 *                                                          just past a limit may always move back inside
 * step: q, q_ref (nq), mu (nv), Jcom (3 x nv, element (r, c) at Jcom[r jc_row + c jc_col]: data.Jcom), com (3:
 * data.com[0]), c_target (3), axes (n_axes ints), q_lo, q_hi (nv - 6); out: H, g, A, b, lo, hi.
 * Returns sole_rows's answer (0: a foot's rotation error is near pi, its rows are the caller's to write). */
CLONED int step_terms(int nv, int m, int count, int n_axes, int r0, int j_row, int j_col, int jc_row, int jc_col,
                      double free_, void *const *markers, void *const *layout, void *const *soles,
                      void *const *step, void *const *out)
{
    const double *q = step[0], *q_ref = step[1], *mu = step[2], *Jcom = step[3], *com = step[4],
                 *c_target = step[5], *q_lo = step[7], *q_hi = step[8];
    const int *axes = step[6];
    double *g = out[1], *A = out[2], *b = out[3], *lo = out[4], *hi = out[5];
    markers_(nv, m, j_row, j_col, markers, layout, out);
    const int soles_ok = soles_(nv, count, j_row, j_col, soles, out + 2);
    for (int i = 6; i < nv; ++i)
        g[i] += mu[i] * (q[i + 1] - q_ref[i + 1]);
    for (int a = 0; a < n_axes; ++a) {
        double *row = A + (size_t)(r0 + a) * nv;
        for (int c = 0; c < nv; ++c)
            row[c] = Jcom[axes[a] * jc_row + c * jc_col];
        b[r0 + a] = c_target[axes[a]] - com[axes[a]];
    }
    for (int i = 0; i < 6; ++i) {
        lo[i] = -free_;
        hi[i] = free_;
    }
    for (int j = 0; j < nv - 6; ++j) {
        const double l = q_lo[j] - q[7 + j], h = q_hi[j] - q[7 + j];
        lo[6 + j] = l < 0.0 ? l : 0.0;
        hi[6 + j] = h > 0.0 ? h : 0.0;
    }
    return soles_ok;
}
