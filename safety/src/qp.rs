//! The velocity-level QP safety filter, solved by clarabel with a fixed sparsity pattern.
//!
//! ```text
//! minimize    1/2 ||qdot - qdot_nom||^2
//! subject to  nhat^T (J qdot - v_B) >= -gamma (d - d_min)    one row per pair (padded)
//!             -nhat^T J qdot <= v_pfl                          within the PFL distance
//!             lb <= qdot <= ub                                 velocity, acceleration and
//!                                                              position limits
//! ```
//!
//! With `qdot` as the variable, gamma is a rate (1/s); the v_B term is the human's own
//! approach speed, which filters that assume a static obstacle leave out.
//!
//! A human can approach faster than the arm can retreat; then no command satisfies every
//! row. The pair rows therefore share one slack `s >= 0` with an exact penalty `rho s` in
//! the cost, each row relaxed by `w_i s` with `w_i` proportional to `max(d_i - d_min, 0) +
//! w_0` (1 for the closest pair): whenever
//! the hard problem is feasible its solution is returned unchanged (`s = 0`), and otherwise
//! the command that minimises the largest weighted violation. A pair with room to spare
//! gives way first, the closest pair last (its row is nearly hard): relaxing row i by
//! `(d_i - d_min) s` is the same as raising its barrier rate from gamma to gamma + s. The
//! arm thus moves away from the closest part as fast as its limits allow instead of trading
//! that pair's distance against a far one. The caller decides what violation of the closest
//! pair's row is acceptable ([`crate::FilterConfig::max_relaxation_m_s`]).
//!
//! Rows of anticipated copies of the human's parts ([`PairConstraint::anticipated`]) rank
//! after the parts' own and the obstacles' when the rows run out, never get a smaller slack
//! weight than the closest part's row, and are not the row whose violation is returned.
//!
//! Power and force limiting needs no rows of its own: its cap on the approach speed of a
//! pair's witness point has the same coefficients as the pair's barrier row, so each row's
//! bound is the smaller of the two ([`PairConstraint::approach_bound_m_s`]). A row that its
//! cap binds gets no slack: slowing down never needs relaxing, and a relaxed cap would let
//! the arm hit one part at full speed while it evades another.
//!
//! clarabel's form is `A x + s = b, s >= 0`, so every row is written as `a^T qdot <= b`.
//! The matrix `A` has, column by column, `max_pairs` pair entries (explicit zeros on unused
//! rows) and the two bound entries: its pattern never changes, so the solver is built once
//! and each tick only overwrites values (presolve, equilibration and zero dropping off, as
//! clarabel requires for data updates).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};

use crate::distance::PairConstraint;
use crate::error::{Result, SafetyError};

/// The QP of one robot, built once.
pub struct QpFilter {
    dof: usize,
    max_pairs: usize,
    solver: DefaultSolver<f64>,
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    p_diagonal: Vec<f64>,
    a_values: Vec<f64>,
    b: Vec<f64>,
    q: Vec<f64>,
}

/// The data of the last QP in clarabel's form, `min 1/2 x^T P x + q^T x  s.t.  A x <= b`
/// (A in compressed sparse columns, P diagonal), to hand the same problem to another solver.
#[derive(Debug, Clone, PartialEq)]
pub struct QpProblem {
    pub p_diagonal: Vec<f64>,
    pub q: Vec<f64>,
    pub a_rows: usize,
    pub a_colptr: Vec<usize>,
    pub a_rowval: Vec<usize>,
    pub a_values: Vec<f64>,
    pub b: Vec<f64>,
}

impl std::fmt::Debug for QpFilter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QpFilter")
            .field("dof", &self.dof)
            .field("max_pairs", &self.max_pairs)
            .finish_non_exhaustive()
    }
}

/// Why a QP solve gave no usable command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpFailure {
    /// The solver ended with this status instead of `Solved`.
    Status(SolverStatus),
    /// The solver said `Solved` but the answer is not finite or breaks a row by more than
    /// the tolerance.
    BadSolution,
}

impl std::fmt::Display for QpFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            QpFailure::Status(s) => write!(f, "solver status {s:?}"),
            QpFailure::BadSolution => f.write_str("solution breaks a constraint"),
        }
    }
}

/// Tolerance on a row of the returned solution, in the row's units (m/s or rad/s).
const ROW_TOLERANCE: f64 = 1e-5;
/// Cost of one m/s of slack in the closest pair's row: far above any multiplier of a row at
/// these scales (the exact penalty then reproduces the hard solution whenever one exists).
const SLACK_WEIGHT: f64 = 1e4;
/// A pair's slack weight is its room `max(d - d_min, 0)` plus this, m: pairs at d_min still
/// give way in proportion, so that a command exists even when none can be kept.
const SLACK_FLOOR_M: f64 = 0.01;
/// Small quadratic weight on the slack, keeping the cost strictly convex.
const SLACK_CURVATURE: f64 = 1e-6;

impl QpFilter {
    /// A filter for `dof` joints with room for `max_pairs` pair rows.
    ///
    /// # Errors
    /// [`SafetyError::Solver`] if clarabel refuses the setup (a bug).
    pub fn new(dof: usize, max_pairs: usize) -> Result<Self> {
        // Variables: qdot (dof), then the slack s. Rows: the pairs, qdot <= ub, -qdot <= -lb,
        // -s <= 0.
        let n = dof + 1;
        let m = max_pairs + 2 * dof + 1;
        let mut p_diagonal = vec![1.0; n];
        p_diagonal[dof] = SLACK_CURVATURE;
        let p = CscMatrix::new(
            n,
            n,
            (0..=n).collect(),
            (0..n).collect(),
            p_diagonal.clone(),
        );
        let per_column = max_pairs + 2;
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rowval = Vec::with_capacity(dof * per_column + max_pairs + 1);
        let mut a_values = Vec::with_capacity(rowval.capacity());
        for j in 0..dof {
            colptr.push(j * per_column);
            rowval.extend(0..max_pairs);
            a_values.extend(std::iter::repeat_n(0.0, max_pairs));
            rowval.push(max_pairs + j); // qdot_j <= ub_j
            a_values.push(1.0);
            rowval.push(max_pairs + dof + j); // -qdot_j <= -lb_j
            a_values.push(-1.0);
        }
        colptr.push(dof * per_column);
        rowval.extend(0..max_pairs); // every pair row: ... - s <= b_i
        a_values.extend(std::iter::repeat_n(-1.0, max_pairs));
        rowval.push(max_pairs + 2 * dof); // -s <= 0
        a_values.push(-1.0);
        colptr.push(rowval.len());
        let a = CscMatrix::new(m, n, colptr.clone(), rowval.clone(), a_values.clone());
        let b = vec![1.0; m];
        let mut q = vec![0.0; n];
        q[dof] = SLACK_WEIGHT;
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .equilibrate_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(60)
            .build()
            .map_err(|e| SafetyError::Solver {
                message: e.to_string(),
            })?;
        let mut b_init = b.clone();
        b_init[m - 1] = 0.0;
        let solver = DefaultSolver::new(&p, &q, &a, &b_init, &[NonnegativeConeT(m)], settings)
            .map_err(|e| SafetyError::Solver {
                message: e.to_string(),
            })?;
        Ok(Self {
            dof,
            max_pairs,
            solver,
            colptr,
            rowval,
            p_diagonal,
            a_values,
            b: b_init,
            q,
        })
    }

    /// The problem of the last [`QpFilter::solve`] call.
    #[must_use]
    pub fn problem(&self) -> QpProblem {
        QpProblem {
            p_diagonal: self.p_diagonal.clone(),
            q: self.q.clone(),
            a_rows: self.b.len(),
            a_colptr: self.colptr.clone(),
            a_rowval: self.rowval.clone(),
            a_values: self.a_values.clone(),
            b: self.b.clone(),
        }
    }

    /// Pair rows the QP has room for.
    #[must_use]
    pub fn max_pairs(&self) -> usize {
        self.max_pairs
    }

    /// Solves for the command closest to `qdot_nom` within `lb..=ub` that keeps every pair
    /// of `pairs` from closing faster than `gamma_per_s (d - d_min_m)` and from approaching
    /// faster than its PFL cap. When there are more pairs than rows, the closest ones are
    /// kept (`pairs` is reordered). Writes the command into `qdot` and returns the
    /// violation: 0 when every row holds, otherwise by how much (m/s) the least-violating
    /// command breaks the closest pair's row.
    ///
    /// # Errors
    /// [`QpFailure`] when the solver does not return a solution that satisfies every row:
    /// the caller must then brake.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        qdot_nom: &[f64],
        pairs: &mut [PairConstraint],
        lb: &[f64],
        ub: &[f64],
        gamma_per_s: f64,
        d_min_m: f64,
        qdot: &mut [f64],
    ) -> std::result::Result<f64, QpFailure> {
        let (n, rows) = (self.dof, self.max_pairs);
        let per_column = rows + 2;
        if pairs.len() > rows {
            // The human's pairs first, closest first; then the obstacles; anticipated copies
            // of the human's parts fill the rows left.
            let rank = |c: &PairConstraint| u8::from(c.obstacle) + 2 * u8::from(c.anticipated);
            pairs.select_nth_unstable_by(rows - 1, |x, y| {
                rank(x)
                    .cmp(&rank(y))
                    .then(x.pair.distance_m.total_cmp(&y.pair.distance_m))
            });
        }
        let used = pairs.len().min(rows);
        // Slack weights relative to the closest pair's (1 for it): the slack stays in m/s
        // of the closest row, which keeps the solver's accuracy where it matters. An
        // anticipated copy never weighs less than it (it gives way no later than the part
        // where it is), and is the reference only when no part has a row.
        let room = |c: &PairConstraint| (c.pair.distance_m - d_min_m).max(0.0) + SLACK_FLOOR_M;
        let closest_room = |anticipated: bool| {
            pairs[..used]
                .iter()
                .filter(|c| !c.obstacle && c.anticipated == anticipated)
                .map(room)
                .fold(f64::INFINITY, f64::min)
        };
        let closest_room = match closest_room(false) {
            r if r.is_finite() => r,
            _ => closest_room(true),
        };
        for i in 0..rows {
            let slack_entry = n * per_column + i;
            if let Some(c) = pairs.get(i) {
                for j in 0..n {
                    self.a_values[j * per_column + i] = -c.normal_jacobian[j];
                }
                self.b[i] = c.approach_bound_m_s(gamma_per_s, d_min_m);
                // A row bound by its PFL cap stays hard: slowing down is always possible. So
                // do obstacle rows: the furniture does not give way.
                let capped = c.obstacle
                    || c.max_approach_m_s
                        < gamma_per_s * (c.pair.distance_m - d_min_m - c.escape_margin_m)
                            - c.human_normal_speed_m_s;
                let weight = room(c) / closest_room;
                self.a_values[slack_entry] = if capped {
                    0.0
                } else if c.anticipated {
                    -weight.max(1.0)
                } else {
                    -weight
                };
            } else {
                for j in 0..n {
                    self.a_values[j * per_column + i] = 0.0;
                }
                self.b[i] = 1.0;
                self.a_values[slack_entry] = -1.0;
            }
        }
        for j in 0..n {
            self.b[rows + j] = ub[j];
            self.b[rows + n + j] = -lb[j];
            self.q[j] = -qdot_nom[j];
        }
        let updated = self
            .solver
            .update_A(&self.a_values)
            .and_then(|()| self.solver.update_b(&self.b))
            .and_then(|()| self.solver.update_q(&self.q));
        if updated.is_err() {
            return Err(QpFailure::Status(SolverStatus::Unsolved));
        }
        self.solver.solve();
        let status = self.solver.solution.status;
        if status != SolverStatus::Solved {
            return Err(QpFailure::Status(status));
        }
        let x = &self.solver.solution.x;
        if x.iter().any(|v| !v.is_finite()) {
            return Err(QpFailure::BadSolution);
        }
        let slack = x[n].max(0.0);
        // Check every row ourselves: a safety command is never taken on trust. What the
        // caller judges is the violation of the closest pair's row (the far rows give way
        // first, on purpose).
        let (mut violation, mut closest) = (0.0, f64::INFINITY);
        for (i, c) in pairs.iter().enumerate().take(used) {
            let lhs: f64 = (0..n)
                .map(|j| self.a_values[j * per_column + i] * x[j])
                .sum();
            let weight = -self.a_values[n * per_column + i];
            if lhs > self.b[i] + weight * slack + ROW_TOLERANCE {
                return Err(QpFailure::BadSolution);
            }
            if !c.obstacle && !c.anticipated && c.pair.distance_m < closest {
                closest = c.pair.distance_m;
                violation = (lhs - self.b[i]).max(0.0);
            }
        }
        for j in 0..n {
            if x[j] > ub[j] + ROW_TOLERANCE || x[j] < lb[j] - ROW_TOLERANCE {
                return Err(QpFailure::BadSolution);
            }
            // Clarabel's interior point stops within its tolerance of the boundary.
            qdot[j] = x[j].clamp(lb[j], ub[j]);
        }
        // Below the solver's tolerance the command keeps every row.
        Ok(if violation > ROW_TOLERANCE {
            violation
        } else {
            0.0
        })
    }
}
