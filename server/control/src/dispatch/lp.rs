//! A small sparse LP/QP model and its solve with clarabel.
//!
//! **Owns:** turning "variables with bounds, linear rows, a linear cost and an
//! optional convex quadratic term" into clarabel's conic form, running it with
//! tight tolerances, mapping its status, clipping the answer into the variable
//! bounds, and checking every row of the answer against a tolerance.
//!
//! **Must not touch:** anything dispatch-specific. The single-period and
//! horizon problems build a [`Model`] and repair their own equalities after
//! the solve (an interior-point answer is not an exact vertex); this module then
//! re-checks the whole model so nothing unchecked leaves the crate.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

/// Every returned solution satisfies every row and bound within this (kW, kWh).
pub(crate) const FEAS_TOL: f64 = 1e-6;

/// A variable whose bounds are closer than this is fixed (an equality row), so
/// that clarabel never sees an empty-interior pair of inequalities.
const FIXED_TOL: f64 = 1e-12;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Sense {
    /// `a·x = rhs`
    Eq,
    /// `a·x <= rhs`
    Le,
}

#[derive(Debug, Clone)]
pub(crate) struct Row {
    pub coefs: Vec<(usize, f64)>,
    pub sense: Sense,
    pub rhs: f64,
    /// What the row means, for error messages ("balance in period 3").
    pub name: String,
}

impl Row {
    pub fn value(&self, x: &[f64]) -> f64 {
        self.coefs.iter().map(|&(j, a)| a * x[j]).sum()
    }
    /// How far `x` is outside the row (0 when satisfied).
    pub fn violation(&self, x: &[f64]) -> f64 {
        let v = self.value(x) - self.rhs;
        match self.sense {
            Sense::Eq => v.abs(),
            Sense::Le => v.max(0.0),
        }
    }
}

/// A minimisation `c·x + ½ xᵀPx` over bounded variables and linear rows.
#[derive(Debug, Clone, Default)]
pub(crate) struct Model {
    pub lb: Vec<f64>,
    pub ub: Vec<f64>,
    pub cost: Vec<f64>,
    pub names: Vec<String>,
    /// Upper-triangle entries (i <= j) of P; duplicates are summed.
    pub quad: Vec<(usize, usize, f64)>,
    /// Constant added to the objective (from expanding squared differences).
    pub constant: f64,
    pub rows: Vec<Row>,
}

/// A solve's point and row prices, or why there is none.
type Solved = Result<(Vec<f64>, Vec<f64>), SolveFailure>;

/// Why a model has no answer.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum SolveFailure {
    Infeasible(String),
    Solver(String),
}

impl Model {
    pub fn var(&mut self, name: String, lb: f64, ub: f64, cost: f64) -> usize {
        self.lb.push(lb);
        self.ub.push(ub);
        self.cost.push(cost);
        self.names.push(name);
        self.lb.len() - 1
    }

    pub fn row(&mut self, name: String, coefs: Vec<(usize, f64)>, sense: Sense, rhs: f64) {
        self.rows.push(Row {
            coefs,
            sense,
            rhs,
            name,
        });
    }

    pub fn n(&self) -> usize {
        self.lb.len()
    }

    pub fn objective(&self, x: &[f64]) -> f64 {
        let lin: f64 = self.cost.iter().zip(x).map(|(c, v)| c * v).sum();
        let quad: f64 = self
            .quad
            .iter()
            .map(|&(i, j, p)| {
                if i == j {
                    0.5 * p * x[i] * x[i]
                } else {
                    p * x[i] * x[j]
                }
            })
            .sum();
        lin + quad + self.constant
    }

    /// Adds `w·(a·x − c)²` to the objective (`a` sparse, no repeated index).
    pub fn add_square(&mut self, w: f64, a: &[(usize, f64)], c: f64) {
        for (p, &(i, ai)) in a.iter().enumerate() {
            for &(j, aj) in &a[p..] {
                // ½xᵀPx with P = 2w·aaᵀ: diagonal ½·2w·aᵢ², off-diagonal 2w·aᵢaⱼ.
                let (lo, hi) = if i <= j { (i, j) } else { (j, i) };
                self.quad.push((lo, hi, 2.0 * w * ai * aj));
            }
            self.cost[i] -= 2.0 * w * c * ai;
        }
        self.constant += w * c * c;
    }

    /// Clips every variable into its bounds.
    pub fn clip(&self, x: &mut [f64]) {
        for (j, v) in x.iter_mut().enumerate() {
            *v = v.clamp(self.lb[j], self.ub[j]);
        }
    }

    /// Snaps each variable within 1e-7 (relative) of a bound onto it: the
    /// vertex an exact LP solver would give. Only for models whose rows the
    /// caller re-closes afterwards (a snapped flow would shift a state of
    /// charge integrated over many periods).
    pub fn snap(&self, x: &mut [f64]) {
        for (j, v) in x.iter_mut().enumerate() {
            let (lo, hi) = (self.lb[j], self.ub[j]);
            if (*v - lo).abs() <= 1e-7 * lo.abs().max(1.0) {
                *v = lo;
            } else if (hi - *v).abs() <= 1e-7 * hi.abs().max(1.0) {
                *v = hi;
            }
        }
    }

    /// The first bound or row that `x` violates by more than `tol`.
    pub fn check(&self, x: &[f64], tol: f64) -> Result<(), String> {
        for (j, v) in x.iter().enumerate() {
            if !v.is_finite() {
                return Err(format!("{} is not a finite number", self.names[j]));
            }
            if *v < self.lb[j] - tol || *v > self.ub[j] + tol {
                return Err(format!(
                    "{} = {v} is outside [{}, {}]",
                    self.names[j], self.lb[j], self.ub[j]
                ));
            }
        }
        for r in &self.rows {
            let viol = r.violation(x);
            if viol > tol {
                return Err(format!("{} is violated by {viol:.3e}", r.name));
            }
        }
        Ok(())
    }

    /// Solves with clarabel and clips the answer into the bounds. The caller
    /// repairs its equalities and then calls [`Model::check`].
    pub fn solve(&self) -> Result<Vec<f64>, SolveFailure> {
        self.solve_with_prices().map(|(x, _)| x)
    }

    /// [`Model::solve`], plus each row's price: how much the optimal
    /// objective falls per unit increase of the row's right-hand side
    /// (`−∂objective/∂rhs`, the negated Lagrange multiplier), in `self.rows`
    /// order. The horizon reads the worth of stored energy off it.
    pub fn solve_with_prices(&self) -> Result<(Vec<f64>, Vec<f64>), SolveFailure> {
        self.solve_to(1e-10)
    }

    /// A relaxation inside branch and bound: looser tolerances, since its
    /// answer only bounds and guides the search (the chosen commitment is
    /// solved again at full precision).
    ///
    /// First without iterative refinement of the KKT solves (a branch and
    /// bound solves hundreds of these, and the refinement is about 40 % of
    /// each: docs/BENCHMARKS.md); only an answer the solver calls clean
    /// (solved, or proven infeasible) is taken from that pass, anything
    /// else is solved again with refinement, so a numerically hard node is
    /// never dropped as infeasible on a rough solve.
    pub fn solve_relaxation(&self) -> Result<Vec<f64>, SolveFailure> {
        const TOL: f64 = 1e-8;
        match self.solve_with(TOL, false) {
            (true, r) => r,
            (false, _) => self.solve_to(TOL),
        }
        .map(|(x, _)| x)
    }

    fn solve_to(&self, tol: f64) -> Solved {
        self.solve_with(tol, true).1
    }

    /// Solves to `tol`, with or without iterative refinement; the flag says
    /// whether clarabel ended cleanly (solved, or primal infeasible with a
    /// certificate) rather than "almost" or not at all.
    fn solve_with(&self, tol: f64, refine: bool) -> (bool, Solved) {
        let n = self.n();
        // Where each of `self.rows` lands in clarabel's cone order.
        let mut slot = vec![0usize; self.rows.len()];
        // Rows in cone order: equalities (incl. fixed variables), then inequalities.
        let mut trip: Vec<(usize, usize, f64)> = Vec::new(); // (col, row, val)
        let mut b: Vec<f64> = Vec::new();
        let mut m = 0usize;
        let mut push_row =
            |coefs: &[(usize, f64)], rhs: f64, trip: &mut Vec<_>, b: &mut Vec<f64>| {
                for &(j, a) in coefs {
                    if a != 0.0 {
                        trip.push((j, m, a));
                    }
                }
                b.push(rhs);
                m += 1;
            };
        for (i, r) in self.rows.iter().enumerate() {
            if r.sense == Sense::Eq {
                slot[i] = b.len();
                push_row(&r.coefs, r.rhs, &mut trip, &mut b);
            }
        }
        let fixed: Vec<bool> = (0..n)
            .map(|j| self.ub[j] - self.lb[j] <= FIXED_TOL)
            .collect();
        for j in (0..n).filter(|&j| fixed[j]) {
            push_row(&[(j, 1.0)], self.lb[j], &mut trip, &mut b);
        }
        let m_eq = b.len();
        for (i, r) in self.rows.iter().enumerate() {
            if r.sense == Sense::Le {
                slot[i] = b.len();
                push_row(&r.coefs, r.rhs, &mut trip, &mut b);
            }
        }
        for j in (0..n).filter(|&j| !fixed[j]) {
            if self.ub[j].is_finite() {
                push_row(&[(j, 1.0)], self.ub[j], &mut trip, &mut b);
            }
            if self.lb[j].is_finite() {
                push_row(&[(j, -1.0)], -self.lb[j], &mut trip, &mut b);
            }
        }
        let m_total = b.len();
        let a = csc(m_total, n, trip);
        let p = csc(
            n,
            n,
            self.quad
                .iter()
                .map(|&(i, j, v)| if i <= j { (j, i, v) } else { (i, j, v) })
                .collect(),
        );
        let mut cones: Vec<SupportedConeT<f64>> = Vec::with_capacity(2);
        if m_eq > 0 {
            cones.push(SupportedConeT::ZeroConeT(m_eq));
        }
        if m_total > m_eq {
            cones.push(SupportedConeT::NonnegativeConeT(m_total - m_eq));
        }
        // Tight tolerances: the answer must match an exact LP solver's objective
        // to 1e-6 relative and every row to 1e-6 absolute after clipping.
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .max_iter(200)
            .tol_gap_abs(tol)
            .tol_gap_rel(tol)
            .tol_feas(tol)
            .tol_ktratio(tol * 100.0)
            .presolve_enable(true)
            .iterative_refinement_enable(refine)
            .build();
        let settings = match settings {
            Ok(s) => s,
            Err(e) => {
                return (
                    false,
                    Err(SolveFailure::Solver(format!("solver settings: {e:?}"))),
                )
            }
        };
        let mut solver = match DefaultSolver::new(&p, &self.cost, &a, &b, &cones, settings) {
            Ok(s) => s,
            Err(e) => {
                return (
                    false,
                    Err(SolveFailure::Solver(format!("solver setup: {e}"))),
                )
            }
        };
        solver.solve();
        let sol = &solver.solution;
        let clean = matches!(
            sol.status,
            SolverStatus::Solved | SolverStatus::PrimalInfeasible
        );
        let result = match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {
                let mut x = sol.x.clone();
                if x.len() != n || x.iter().any(|v| !v.is_finite()) {
                    return (
                        false,
                        Err(SolveFailure::Solver(
                            "solver returned a non-finite point".into(),
                        )),
                    );
                }
                self.clip(&mut x);
                // clarabel solves min c·x s.t. Ax + s = b, s ∈ K, whose
                // multiplier z gives ∂objective/∂b = −z.
                let prices = slot
                    .iter()
                    .map(|&k| {
                        sol.z
                            .get(k)
                            .copied()
                            .filter(|z| z.is_finite())
                            .unwrap_or(0.0)
                    })
                    .collect();
                Ok((x, prices))
            }
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                Err(SolveFailure::Infeasible(
                    "the solver proved that no setpoints satisfy every constraint \
                     (balance, unit limits, ramps, state of charge) together"
                        .into(),
                ))
            }
            other => Err(SolveFailure::Solver(format!(
                "solver stopped without an answer: {other:?}"
            ))),
        };
        (clean, result)
    }
}

/// A CSC matrix from (col, row, val) triplets; duplicates are summed.
fn csc(m: usize, n: usize, mut trip: Vec<(usize, usize, f64)>) -> CscMatrix<f64> {
    trip.sort_by_key(|t| (t.0, t.1));
    let mut colptr = vec![0usize; n + 1];
    let mut rowval: Vec<usize> = Vec::with_capacity(trip.len());
    let mut nzval: Vec<f64> = Vec::with_capacity(trip.len());
    let mut last: Option<(usize, usize)> = None;
    for (c, r, v) in trip {
        if last == Some((c, r)) {
            if let Some(z) = nzval.last_mut() {
                *z += v;
            }
            continue;
        }
        rowval.push(r);
        nzval.push(v);
        colptr[c + 1] += 1;
        last = Some((c, r));
    }
    for j in 0..n {
        colptr[j + 1] += colptr[j];
    }
    CscMatrix::new(m, n, colptr, rowval, nzval)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_lp_to_tight_tolerance() {
        // min -x - y  s.t. x + y <= 1.5, x in [0,1], y in [0,1]
        let mut m = Model::default();
        let x = m.var("x".into(), 0.0, 1.0, -1.0);
        let y = m.var("y".into(), 0.0, 1.0, -1.0);
        m.row("cap".into(), vec![(x, 1.0), (y, 1.0)], Sense::Le, 1.5);
        let sol = m.solve().unwrap();
        assert!((m.objective(&sol) + 1.5).abs() < 1e-9);
        m.check(&sol, FEAS_TOL).unwrap();
    }

    #[test]
    fn row_prices_are_the_objective_sensitivity_to_the_rhs() {
        // min 2x + 5y  s.t. x + y = d, x <= 3: the marginal unit of d costs 5
        // (y), and one more unit of x's capacity saves 3.
        let build = |d: f64, cap: f64| {
            let mut m = Model::default();
            let x = m.var("x".into(), 0.0, f64::INFINITY, 2.0);
            let y = m.var("y".into(), 0.0, f64::INFINITY, 5.0);
            m.row("demand".into(), vec![(x, 1.0), (y, 1.0)], Sense::Eq, d);
            m.row("cap".into(), vec![(x, 1.0)], Sense::Le, cap);
            m
        };
        let m = build(10.0, 3.0);
        let (x, prices) = m.solve_with_prices().unwrap();
        let f = |m: &Model| {
            let x = m.solve().unwrap();
            m.objective(&x)
        };
        let base = m.objective(&x);
        let d_demand = f(&build(10.001, 3.0)) - base;
        let d_cap = f(&build(10.0, 3.001)) - base;
        assert!((prices[0] + d_demand / 0.001).abs() < 1e-4, "{prices:?}");
        assert!((prices[1] + d_cap / 0.001).abs() < 1e-4, "{prices:?}");
        assert!((prices[0] + 5.0).abs() < 1e-6 && (prices[1] - 3.0).abs() < 1e-6);
    }

    #[test]
    fn reports_infeasibility() {
        let mut m = Model::default();
        let x = m.var("x".into(), 2.0, 3.0, 1.0);
        m.row("x=1".into(), vec![(x, 1.0)], Sense::Eq, 1.0);
        assert!(matches!(m.solve(), Err(SolveFailure::Infeasible(_))));
    }

    #[test]
    fn fixed_variables_and_quadratic_terms() {
        // min (x-1)^2 = x^2 - 2x (+1), z fixed at 4, x + z = w, w in [0, 10]
        let mut m = Model::default();
        let x = m.var("x".into(), -5.0, 5.0, -2.0);
        let z = m.var("z".into(), 4.0, 4.0, 0.0);
        let w = m.var("w".into(), 0.0, 10.0, 0.0);
        m.quad.push((x, x, 2.0));
        m.row(
            "sum".into(),
            vec![(x, 1.0), (z, 1.0), (w, -1.0)],
            Sense::Eq,
            0.0,
        );
        let sol = m.solve().unwrap();
        assert!((sol[x] - 1.0).abs() < 1e-6);
        assert!((sol[w] - 5.0).abs() < 1e-6);
        m.check(&sol, FEAS_TOL).unwrap();
    }
}
