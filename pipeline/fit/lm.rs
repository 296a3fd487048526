//! Levenberg-Marquardt for nonlinear least squares, written as an argmin
//! [`Solver`] so it runs in argmin's `Executor` like the built-in solvers
//! (argmin 0.11 has Gauss-Newton, which fails from far starts, but no
//! damped method).
//!
//! Each iteration solves (J^T J + lambda D) delta = -J^T r, D Marquardt's
//! diagonal scaling (the running maximum of diag(J^T J)); a rejected step
//! raises lambda and is tried again within the iteration. Convergence is
//! judged from the undamped (Gauss-Newton) step at each accepted point
//! (`ftol` on the cost, `xtol` on its scaled size), so that a heavily
//! damped, tiny step does not pass for it. Box bounds by projection.
//! `LevenbergMarquardt` takes residuals and J; a problem that gives J^T J
//! and J^T r itself gives `Normal`. The algorithm and its references
//! (Marquardt 1963; Moré 1978): docs/methods.md, "Levenberg-Marquardt".

use argmin::core::{
    ArgminError, Error, IterState, Jacobian, KV, Operator, Problem, Solver, TerminationReason,
    TerminationStatus,
};
use argmin::kv;
use nalgebra::{DMatrix, DVector};

/// The argmin state the solver works on: parameters, Jacobian and residuals
/// as nalgebra types; the cost is the sum of squared residuals.
pub type LmState = IterState<DVector<f64>, (), DMatrix<f64>, (), DVector<f64>, f64>;

/// Levenberg-Marquardt solver (see the module documentation).
#[derive(Debug, Clone)]
pub struct LevenbergMarquardt {
    lambda0: f64,
    factor: f64,
    lambda_max: f64,
    ftol: f64,
    xtol: f64,
    lower: Option<DVector<f64>>,
    upper: Option<DVector<f64>>,
    lambda: f64,
    diag: DVector<f64>,
    /// For a problem that gives residuals and J: J^T J and J^T r at the
    /// current point, formed once when the point is accepted (its
    /// convergence test needs them) and used by the next iteration's steps.
    /// A problem that gives its normal equations keeps them in the state.
    normal: Option<(DMatrix<f64>, DVector<f64>)>,
    status: TerminationStatus,
    /// Whether the next run goes on from where the last one stopped
    /// ([`Self::resumed`]).
    resume: bool,
    /// How many accepted steps in a row may each lower the cost by at most
    /// `ftol` relative before the run stops unconverged
    /// ([`Self::with_stall_limit`]); None: no such stop.
    stall_limit: Option<u32>,
    /// Accepted steps in a row that lowered the cost by at most `ftol`.
    stalled: u32,
    /// A predicted reduction below which a point no damping improves on
    /// is an optimum ([`Self::with_settled_cost`]); None: no such point.
    settled: Option<f64>,
}

impl Default for LevenbergMarquardt {
    fn default() -> Self {
        Self::new()
    }
}

/// J^T J and J^T r, without a transposed copy of the tall J.
fn normal_equations(j: &DMatrix<f64>, r: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
    (j.tr_mul(j), j.tr_mul(r))
}

fn invalid(text: String) -> Error {
    ArgminError::InvalidParameter { text }.into()
}

impl LevenbergMarquardt {
    /// lambda starts at 1e-3 (Marquardt's choice) and moves by factors of
    /// 10; ftol = 1e-12, xtol = 1e-10. With ftol = 1e-12 an accepted point
    /// is within about sqrt(1e-12 (2N - p)) standard deviations of the
    /// optimum (1.5e-5 for the paper's 119 bins): far below the noise, so
    /// different starts agree to many digits.
    pub fn new() -> Self {
        Self {
            lambda0: 1e-3,
            factor: 10.0,
            lambda_max: 1e16,
            ftol: 1e-12,
            xtol: 1e-10,
            lower: None,
            upper: None,
            lambda: 1e-3,
            diag: DVector::zeros(0),
            normal: None,
            status: TerminationStatus::NotTerminated,
            resume: false,
            stall_limit: None,
            stalled: 0,
            settled: None,
        }
    }

    /// Stop, unconverged, after `steps` accepted steps in a row that each
    /// lowered the cost by at most `ftol` relative while the undamped step
    /// still predicted more. That is a direction the data do not fix: a
    /// mode's frequency or a piston's mass running off to where no bin sees
    /// it, each step accepted for a change in the cost's last digits. Left
    /// alone such a run takes every iteration it is allowed, several trial
    /// points each; it ends unconverged either way.
    pub fn with_stall_limit(mut self, steps: u32) -> Self {
        self.stall_limit = Some(steps.max(1));
        self
    }

    /// Where no damping finds a lower cost and the undamped step predicts
    /// a reduction of at most `cost`, the run has converged. For a cost in
    /// chi-square units (residuals over their stds) a reduction of 1e-6
    /// is a parameter 1e-3 of its std from the optimum: far below what the
    /// data tell, while the relative `ftol` may ask for digits that
    /// rounding of a very precise fit's residuals does not hold.
    pub fn with_settled_cost(mut self, cost: f64) -> Self {
        self.settled = Some(cost);
        self
    }

    /// Relative tolerances on the cost reduction and on the step size; both
    /// must be positive and finite.
    pub fn with_tolerances(mut self, ftol: f64, xtol: f64) -> Result<Self, Error> {
        for (name, v) in [("ftol", ftol), ("xtol", xtol)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(format!(
                    "Levenberg-Marquardt: {name} must be positive and finite (got {v})"
                )));
            }
        }
        self.ftol = ftol;
        self.xtol = xtol;
        Ok(self)
    }

    /// Initial damping (positive) and the factor it moves by (above 1).
    pub fn with_lambda(mut self, lambda0: f64, factor: f64) -> Result<Self, Error> {
        if !(lambda0.is_finite() && lambda0 > 0.0) {
            return Err(invalid(format!(
                "Levenberg-Marquardt: the initial lambda must be positive and finite (got {lambda0})"
            )));
        }
        if !(factor.is_finite() && factor > 1.0) {
            return Err(invalid(format!(
                "Levenberg-Marquardt: the lambda factor must be above 1 (got {factor})"
            )));
        }
        self.lambda0 = lambda0;
        self.factor = factor;
        Ok(self)
    }

    /// Box bounds lower <= theta <= upper (use infinities for free
    /// parameters).
    pub fn with_bounds(mut self, lower: DVector<f64>, upper: DVector<f64>) -> Result<Self, Error> {
        if lower.len() != upper.len() {
            return Err(invalid(format!(
                "Levenberg-Marquardt: {} lower bounds but {} upper bounds",
                lower.len(),
                upper.len()
            )));
        }
        if let Some(k) = (0..lower.len())
            .find(|&k| lower[k].is_nan() || upper[k].is_nan() || lower[k] > upper[k])
        {
            return Err(invalid(format!(
                "Levenberg-Marquardt: bound {k} is empty or NaN ([{}, {}])",
                lower[k], upper[k]
            )));
        }
        self.lower = Some(lower);
        self.upper = Some(upper);
        Ok(self)
    }

    /// The damping at the end of the run.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// The solver as a run stopped at its iteration limit left it, made to
    /// go on from there: run it again from that run's last point (and, for
    /// a problem giving its normal equations, with that run's last
    /// [`Normal`] in the state) and its damping and scaling carry over, so
    /// the two runs take exactly the steps one longer run would. Lets a
    /// caller run several starts a few iterations each and follow only the
    /// best further.
    pub fn resumed(mut self) -> Self {
        self.resume = true;
        self
    }

    fn clamp(&self, mut theta: DVector<f64>) -> DVector<f64> {
        if let (Some(lo), Some(hi)) = (&self.lower, &self.upper) {
            for k in 0..theta.len() {
                theta[k] = theta[k].clamp(lo[k], hi[k]);
            }
        }
        theta
    }

    fn pushes_out(&self, theta: &DVector<f64>, k: usize, step: f64) -> bool {
        match (&self.lower, &self.upper) {
            (Some(lo), Some(hi)) => {
                (theta[k] <= lo[k] && step < 0.0) || (theta[k] >= hi[k] && step > 0.0)
            }
            _ => false,
        }
    }

    /// Solves (A + lambda D) delta = -g over the parameters not held at a
    /// bound; `None` when that matrix is not positive definite.
    fn step(
        &self,
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        lambda: f64,
        theta: &DVector<f64>,
    ) -> Option<DVector<f64>> {
        let p = g.len();
        let mut free = vec![true; p];
        loop {
            let idx: Vec<usize> = (0..p).filter(|&k| free[k]).collect();
            let mut delta = DVector::zeros(p);
            if idx.is_empty() {
                return Some(delta);
            }
            let q = idx.len();
            let mut m = DMatrix::zeros(q, q);
            let mut rhs = DVector::zeros(q);
            for (r, &i) in idx.iter().enumerate() {
                for (c, &j) in idx.iter().enumerate() {
                    m[(r, c)] = a[(i, j)];
                }
                m[(r, r)] += lambda * self.diag[i];
                rhs[r] = -g[i];
            }
            let sol = m.cholesky()?.solve(&rhs);
            if sol.iter().any(|v| !v.is_finite()) {
                return None;
            }
            for (r, &i) in idx.iter().enumerate() {
                delta[i] = sol[r];
            }
            let held: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&k| self.pushes_out(theta, k, delta[k]))
                .collect();
            if held.is_empty() {
                return Some(delta);
            }
            for k in held {
                free[k] = false;
            }
        }
    }

    fn update_diag(&mut self, a: &DMatrix<f64>) {
        let p = a.nrows();
        if self.diag.len() != p {
            self.diag = DVector::zeros(p);
        }
        for k in 0..p {
            self.diag[k] = self.diag[k].max(a[(k, k)]);
        }
        // A parameter the residuals do not depend on still gets some damping.
        let floor = 1e-12 * self.diag.max();
        for k in 0..p {
            self.diag[k] = self.diag[k].max(floor);
        }
    }

    /// Whether the undamped step at theta, with cost r^T r and the normal
    /// matrices A = J^T J, g = J^T r there, is negligible.
    fn is_converged(
        &self,
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        cost: f64,
        theta: &DVector<f64>,
    ) -> bool {
        if cost == 0.0 {
            return true;
        }
        let Some(delta) = self.step(a, g, 0.0, theta) else {
            return false;
        };
        // Reduction predicted by the linear model: -(2 g.delta + delta' A delta).
        let pred = -(2.0 * g.dot(&delta) + delta.dot(&(a * &delta)));
        let scaled_norm = |v: &DVector<f64>| {
            v.iter()
                .zip(self.diag.iter())
                .map(|(x, d)| d * x * x)
                .sum::<f64>()
                .sqrt()
        };
        let step = scaled_norm(&delta);
        let size = scaled_norm(theta);
        pred <= self.ftol * cost || step <= self.xtol * (size + self.xtol)
    }
}

/// What a problem that forms its normal equations itself gives the solver:
/// r^T r, J^T J and J^T r at a point, without J. A problem with many
/// residuals and few parameters (the joint fit's tens of thousands of bins
/// against seven parameters) accumulates them residual by residual in the
/// one pass that computes the model, instead of storing a tall J and
/// multiplying it out.
///
/// The solver asks for all three at every trial point, not the cost first
/// and the rest only once the step is accepted: most steps are accepted
/// (every one of the joint fit's plain and delay fits on the seven-run
/// bench, 23 of 30 with the valve mode), and the model and its gradient
/// share nearly all their work, so one pass per trial is cheaper than a
/// cost pass per trial and a second pass per accepted step.
#[derive(Debug, Clone, PartialEq)]
pub struct Normal {
    /// r^T r.
    pub cost: f64,
    /// J^T J.
    pub a: DMatrix<f64>,
    /// J^T r.
    pub g: DVector<f64>,
}

/// The state when the problem gives its cost and normal equations together
/// (as its "Jacobian"), the cost also kept as the state's.
pub type LmNormalState = IterState<DVector<f64>, (), Normal, (), (), f64>;

/// An accepted step: the new point, its cost and what the problem gave with
/// it (the residuals, or nothing).
struct Accepted<X> {
    theta: DVector<f64>,
    cost: f64,
    extra: X,
}

impl LevenbergMarquardt {
    /// An error unless the starting point's cost is finite.
    fn check_start(cost: f64) -> Result<(), Error> {
        if cost.is_finite() {
            return Ok(());
        }
        Err(ArgminError::ConditionViolated {
            text: format!("Levenberg-Marquardt: the cost at the starting point is {cost}"),
        }
        .into())
    }

    /// Sets the damping up from the normal equations at the start.
    fn start(&mut self, cost: f64, a: &DMatrix<f64>, g: &DVector<f64>, theta: &DVector<f64>) {
        let resume = std::mem::take(&mut self.resume) && self.diag.len() == theta.len();
        if !resume {
            self.diag = DVector::zeros(0);
            self.lambda = self.lambda0;
            self.stalled = 0;
        }
        self.update_diag(a);
        self.status = if self.is_converged(a, g, cost, theta) {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        };
    }

    /// The starting point the executor was configured with, checked
    /// against the bounds and clamped into them.
    fn starting_point(&self, theta: Option<DVector<f64>>) -> Result<DVector<f64>, Error> {
        let theta = theta.ok_or_else(|| -> Error {
            ArgminError::NotInitialized {
                text: "Levenberg-Marquardt needs a starting point (Executor::configure)".into(),
            }
            .into()
        })?;
        if let Some(lo) = &self.lower
            && lo.len() != theta.len()
        {
            return Err(invalid(format!(
                "Levenberg-Marquardt: {} bounds for {} parameters",
                lo.len(),
                theta.len()
            )));
        }
        Ok(self.clamp(theta))
    }

    /// One iteration from `theta` (cost `cost`, normal equations `a`, `g`):
    /// damped steps until one lowers the cost (`trial` gives a point's cost
    /// and whatever else the problem computes with it), or `None` when
    /// lambda passes its maximum. Counts the rejected steps.
    fn advance<X>(
        &mut self,
        theta: &DVector<f64>,
        cost: f64,
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        rejected: &mut u64,
        mut trial: impl FnMut(&DVector<f64>) -> Result<(f64, X), Error>,
    ) -> Result<Option<Accepted<X>>, Error> {
        self.update_diag(a);
        while self.lambda <= self.lambda_max {
            if let Some(delta) = self.step(a, g, self.lambda, theta) {
                let point = self.clamp(theta + &delta);
                let (c_new, extra) = trial(&point)?;
                if c_new.is_finite() && c_new < cost {
                    self.lambda = (self.lambda / self.factor).max(1e-15);
                    return Ok(Some(Accepted {
                        theta: point,
                        cost: c_new,
                        extra,
                    }));
                }
            }
            *rejected += 1;
            self.lambda *= self.factor;
        }
        if let Some(floor) = self.settled
            && let Some(delta) = self.step(a, g, 0.0, theta)
            && -(2.0 * g.dot(&delta) + delta.dot(&(a * &delta))) <= floor
        {
            self.status = TerminationStatus::Terminated(TerminationReason::SolverConverged);
            return Ok(None);
        }
        self.status = TerminationStatus::Terminated(TerminationReason::SolverExit(format!(
            "Levenberg-Marquardt: no step lowers the cost (lambda reached {:.1e}); the tolerances may be tighter than the data allow",
            self.lambda
        )));
        Ok(None)
    }

    /// Judges convergence at an accepted point of cost `cost`, reached from
    /// one of cost `previous`, and whether the run has stalled.
    fn accept(
        &mut self,
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        (previous, cost): (f64, f64),
        theta: &DVector<f64>,
    ) {
        if self.is_converged(a, g, cost, theta) {
            self.status = TerminationStatus::Terminated(TerminationReason::SolverConverged);
            return;
        }
        let Some(limit) = self.stall_limit else {
            return;
        };
        if previous - cost <= self.ftol * previous {
            self.stalled += 1;
        } else {
            self.stalled = 0;
        }
        if self.stalled >= limit {
            self.status = TerminationStatus::Terminated(TerminationReason::SolverExit(format!(
                "Levenberg-Marquardt: the cost fell by at most {:e} of itself in each of the last {limit} steps while the undamped step predicted more: a direction the data do not fix",
                self.ftol
            )));
        }
    }

    fn missing(what: &str) -> Error {
        ArgminError::PotentialBug {
            text: format!("Levenberg-Marquardt: {what} not set"),
        }
        .into()
    }
}

impl<O> Solver<O, LmState> for LevenbergMarquardt
where
    O: Operator<Param = DVector<f64>, Output = DVector<f64>>
        + Jacobian<Param = DVector<f64>, Jacobian = DMatrix<f64>>,
{
    fn name(&self) -> &str {
        "Levenberg-Marquardt"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        mut state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let theta = self.starting_point(state.take_param())?;
        let r = problem.apply(&theta)?;
        let cost = r.norm_squared();
        Self::check_start(cost)?;
        let j = problem.jacobian(&theta)?;
        let (a, g) = normal_equations(&j, &r);
        self.start(cost, &a, &g, &theta);
        self.normal = Some((a, g));
        Ok((state.param(theta).residuals(r).jacobian(j).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        mut state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let theta = state.take_param().ok_or_else(|| Self::missing("param"))?;
        let r = state
            .take_residuals()
            .ok_or_else(|| Self::missing("residuals"))?;
        let j = state
            .take_jacobian()
            .ok_or_else(|| Self::missing("jacobian"))?;
        let cost = state.get_cost();
        let (a, g) = match self.normal.take() {
            Some(normal) => normal,
            None => normal_equations(&j, &r),
        };
        let mut rejected = 0_u64;
        let accepted = self.advance(&theta, cost, &a, &g, &mut rejected, |point| {
            let r = problem.apply(point)?;
            Ok((r.norm_squared(), r))
        })?;
        let kv = |lm: &Self| kv!("lambda" => lm.lambda; "rejected" => rejected;);
        match accepted {
            Some(Accepted {
                theta: trial,
                cost: c_new,
                extra: r_new,
            }) => {
                let j_new = problem.jacobian(&trial)?;
                let (a_new, g_new) = normal_equations(&j_new, &r_new);
                self.accept(&a_new, &g_new, (cost, c_new), &trial);
                self.normal = Some((a_new, g_new));
                Ok((
                    state
                        .param(trial)
                        .residuals(r_new)
                        .jacobian(j_new)
                        .cost(c_new),
                    Some(kv(self)),
                ))
            }
            None => {
                self.normal = Some((a, g));
                Ok((
                    state.param(theta).residuals(r).jacobian(j).cost(cost),
                    Some(kv(self)),
                ))
            }
        }
    }

    fn terminate(&mut self, _state: &LmState) -> TerminationStatus {
        self.status.clone()
    }
}

/// The same iterations for a problem whose "Jacobian" is its cost and
/// normal equations ([`Normal`]).
impl<O> Solver<O, LmNormalState> for LevenbergMarquardt
where
    O: Jacobian<Param = DVector<f64>, Jacobian = Normal>,
{
    fn name(&self) -> &str {
        "Levenberg-Marquardt"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        mut state: LmNormalState,
    ) -> Result<(LmNormalState, Option<KV>), Error> {
        let theta = self.starting_point(state.take_param())?;
        // A resumed run is given the last normal equations of the run it
        // goes on from, at this very point.
        let normal = match state.take_jacobian() {
            Some(normal) if self.resume => normal,
            _ => problem.jacobian(&theta)?,
        };
        let cost = normal.cost;
        Self::check_start(cost)?;
        self.start(cost, &normal.a, &normal.g, &theta);
        Ok((state.param(theta).jacobian(normal).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        mut state: LmNormalState,
    ) -> Result<(LmNormalState, Option<KV>), Error> {
        let theta = state.take_param().ok_or_else(|| Self::missing("param"))?;
        let normal = state
            .take_jacobian()
            .ok_or_else(|| Self::missing("normal equations"))?;
        let cost = state.get_cost();
        let mut rejected = 0_u64;
        let accepted =
            self.advance(&theta, cost, &normal.a, &normal.g, &mut rejected, |point| {
                let n = problem.jacobian(point)?;
                Ok((n.cost, n))
            })?;
        let kv = |lm: &Self| kv!("lambda" => lm.lambda; "rejected" => rejected;);
        match accepted {
            Some(Accepted {
                theta: trial,
                cost: c_new,
                extra: n_new,
            }) => {
                self.accept(&n_new.a, &n_new.g, (cost, c_new), &trial);
                Ok((
                    state.param(trial).jacobian(n_new).cost(c_new),
                    Some(kv(self)),
                ))
            }
            None => Ok((
                state.param(theta).jacobian(normal).cost(cost),
                Some(kv(self)),
            )),
        }
    }

    fn terminate(&mut self, _state: &LmNormalState) -> TerminationStatus {
        self.status.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use argmin::core::{Executor, State};

    /// Rosenbrock as least squares: r = (10 (y - x^2), 1 - x); minimum (1, 1).
    struct Rosenbrock;

    impl Operator for Rosenbrock {
        type Param = DVector<f64>;
        type Output = DVector<f64>;
        fn apply(&self, p: &DVector<f64>) -> Result<DVector<f64>, Error> {
            Ok(DVector::from_vec(vec![
                10.0 * (p[1] - p[0] * p[0]),
                1.0 - p[0],
            ]))
        }
    }

    impl Jacobian for Rosenbrock {
        type Param = DVector<f64>;
        type Jacobian = DMatrix<f64>;
        fn jacobian(&self, p: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
            Ok(DMatrix::from_row_slice(
                2,
                2,
                &[-20.0 * p[0], 10.0, -1.0, 0.0],
            ))
        }
    }

    #[test]
    fn solves_rosenbrock_from_the_classic_start() {
        // The textbook start (-1.2, 1) is where undamped Gauss-Newton steps
        // overshoot; the known minimum is (1, 1) with zero cost.
        let res = Executor::new(Rosenbrock, LevenbergMarquardt::new())
            .configure(|s| s.param(DVector::from_vec(vec![-1.2, 1.0])).max_iters(100))
            .run()
            .unwrap();
        let st = res.state();
        assert_eq!(
            st.get_termination_reason(),
            Some(&TerminationReason::SolverConverged)
        );
        let p = st.get_best_param().unwrap();
        assert_relative_eq!(p[0], 1.0, epsilon = 1e-8);
        assert_relative_eq!(p[1], 1.0, epsilon = 1e-8);
    }

    #[test]
    fn a_resumed_run_takes_the_steps_one_longer_run_would() {
        // Rosenbrock from (-1.2, 1) takes some twenty iterations, with
        // rejected steps that raise lambda early on: stopping after 4 and
        // resuming must land on the very point of one run, to the bit, and
        // a fresh (not resumed) second run, which restarts lambda, differs
        // on the way (it is the resumed state that is carried, not chance).
        let run = |lm: LevenbergMarquardt, from: Vec<f64>, iters: u64| {
            Executor::new(Rosenbrock, lm)
                .configure(|s| s.param(DVector::from_vec(from)).max_iters(iters))
                .run()
                .unwrap()
        };
        let path = |lm: LevenbergMarquardt, from: Vec<f64>, iters: u64| {
            let res = run(lm, from, iters);
            let p = res.state().get_param().unwrap().clone();
            (p, res.solver)
        };
        let (whole, _) = path(LevenbergMarquardt::new(), vec![-1.2, 1.0], 8);
        let (first, solver) = path(LevenbergMarquardt::new(), vec![-1.2, 1.0], 4);
        let (resumed, _) = path(solver.resumed(), first.as_slice().to_vec(), 4);
        assert_eq!(resumed, whole);
        let (_, solver) = path(LevenbergMarquardt::new(), vec![-1.2, 1.0], 4);
        let (fresh, _) = path(solver, first.as_slice().to_vec(), 4);
        assert_ne!(fresh, whole);
    }

    /// r = (x - 1, e (1 + exp(-y))): the cost falls towards its floor e^2
    /// as y runs off to infinity, by less at every step, and the undamped
    /// step there, (1 + e^y) in y, predicts the whole second residual as a
    /// gain, so neither test of convergence is ever met: a direction the
    /// data do not fix, as a mode's frequency on a rig without one. Counts
    /// the points it is evaluated at.
    struct Stalling(std::cell::Cell<u32>);

    const E: f64 = 0.1;

    impl Operator for Stalling {
        type Param = DVector<f64>;
        type Output = DVector<f64>;
        fn apply(&self, p: &DVector<f64>) -> Result<DVector<f64>, Error> {
            self.0.set(self.0.get() + 1);
            Ok(DVector::from_vec(vec![
                p[0] - 1.0,
                E * (1.0 + (-p[1]).exp()),
            ]))
        }
    }

    impl Jacobian for Stalling {
        type Param = DVector<f64>;
        type Jacobian = DMatrix<f64>;
        fn jacobian(&self, p: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
            Ok(DMatrix::from_row_slice(
                2,
                2,
                &[1.0, 0.0, 0.0, -E * (-p[1]).exp()],
            ))
        }
    }

    /// Residuals whose last digits do not follow the parameter (a very
    /// precise fit's residuals, each a difference of two large numbers,
    /// rounded): 1e3 (x - 1) on steps of 1e-4 that never reach 0, and 1.
    struct Jittery;

    impl Operator for Jittery {
        type Param = DVector<f64>;
        type Output = DVector<f64>;
        fn apply(&self, p: &DVector<f64>) -> Result<DVector<f64>, Error> {
            Ok(DVector::from_vec(vec![
                1e-4 * ((1e7 * (p[0] - 1.0)).floor() + 0.5),
                1.0,
            ]))
        }
    }

    impl Jacobian for Jittery {
        type Param = DVector<f64>;
        type Jacobian = DMatrix<f64>;
        fn jacobian(&self, _: &DVector<f64>) -> Result<DMatrix<f64>, Error> {
            Ok(DMatrix::from_row_slice(2, 1, &[1e3, 0.0]))
        }
    }

    /// Where the steps hide every further reduction, a run ends with no
    /// step lowering the cost; with a settled cost of 1e-6 (chi-square
    /// units) the same point is an optimum, within 1e-7 of x = 1 as the
    /// steps allow.
    #[test]
    fn a_settled_cost_ends_a_run_rounding_stops_as_converged() {
        let run = |lm: LevenbergMarquardt| {
            let res = Executor::new(Jittery, lm)
                .configure(|s| s.param(DVector::from_vec(vec![3.0])).max_iters(200))
                .run()
                .unwrap();
            let st = res.state();
            (
                st.get_termination_reason().cloned(),
                st.get_param().unwrap()[0],
            )
        };
        let (why, _) = run(LevenbergMarquardt::new());
        assert!(
            matches!(&why, Some(TerminationReason::SolverExit(w)) if w.contains("no step lowers the cost")),
            "{why:?}"
        );
        let (why, x) = run(LevenbergMarquardt::new().with_settled_cost(1e-6));
        assert_eq!(why, Some(TerminationReason::SolverConverged));
        assert!((x - 1.0).abs() <= 1e-7, "{x}");
    }

    #[test]
    fn a_stall_limit_ends_a_run_that_only_creeps() {
        let run = |lm: LevenbergMarquardt| {
            let res = Executor::new(Stalling(std::cell::Cell::new(0)), lm)
                .configure(|s| s.param(DVector::from_vec(vec![3.0, 0.0])).max_iters(200))
                .run()
                .unwrap();
            let evals = res.problem.problem.as_ref().unwrap().0.get();
            let st = res.state();
            let reason = match st.get_termination_reason() {
                Some(TerminationReason::SolverExit(why)) => why.clone(),
                other => panic!("{other:?}"),
            };
            (st.get_cost(), st.get_param().unwrap()[0], evals, reason)
        };
        // Left alone it creeps until no damping finds a lower cost, which
        // takes a score of rejected points at the end.
        let (cost, x, evals, why) = run(LevenbergMarquardt::new());
        assert!(why.contains("no step lowers the cost"), "{why}");
        // With the limit it stops three steps of no gain in, unconverged,
        // at the same cost (the floor e^2 to 1e-12 of itself) in fewer
        // evaluations.
        let (cost_s, x_s, evals_s, why_s) = run(LevenbergMarquardt::new().with_stall_limit(3));
        assert!(why_s.contains("a direction the data do not fix"), "{why_s}");
        assert_relative_eq!(cost, E * E, max_relative = 1e-12);
        assert_relative_eq!(cost_s, E * E, max_relative = 1e-12);
        assert_relative_eq!(x, 1.0, epsilon = 1e-9);
        assert_relative_eq!(x_s, 1.0, epsilon = 1e-9);
        assert!(evals_s * 2 < evals, "{evals_s} evaluations against {evals}");
    }

    #[test]
    fn bound_holds_a_parameter_and_the_rest_still_converges() {
        // With x <= 0.5 the constrained minimum of the Rosenbrock least squares
        // is at x = 0.5, y = x^2 = 0.25 (the first residual can still vanish).
        let lm = LevenbergMarquardt::new()
            .with_bounds(
                DVector::from_vec(vec![f64::NEG_INFINITY, f64::NEG_INFINITY]),
                DVector::from_vec(vec![0.5, f64::INFINITY]),
            )
            .unwrap();
        let res = Executor::new(Rosenbrock, lm)
            .configure(|s| s.param(DVector::from_vec(vec![-1.2, 1.0])).max_iters(200))
            .run()
            .unwrap();
        let p = res.state().get_best_param().unwrap();
        assert_relative_eq!(p[0], 0.5, epsilon = 1e-12);
        assert_relative_eq!(p[1], 0.25, epsilon = 1e-8);
    }

    #[test]
    fn builders_validate_with_messages() {
        let e = LevenbergMarquardt::new()
            .with_tolerances(0.0, 1e-8)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "Invalid parameter: \"Levenberg-Marquardt: ftol must be positive and finite (got 0)\""
        );
        let e = LevenbergMarquardt::new()
            .with_lambda(1e-3, 1.0)
            .unwrap_err();
        assert!(
            e.to_string().contains("factor must be above 1 (got 1)"),
            "{e}"
        );
        let e = LevenbergMarquardt::new()
            .with_bounds(DVector::from_vec(vec![1.0]), DVector::from_vec(vec![0.0]))
            .unwrap_err();
        assert!(e.to_string().contains("bound 0 is empty"), "{e}");
    }
}
