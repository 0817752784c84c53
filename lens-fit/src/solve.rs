//! Runs the stages of a fit (see [`crate::fit`]) and gathers what the report needs: values,
//! uncertainties and correlations from the Jacobian, per-capture residuals, the convergence
//! history.

use crate::fit::{elapsed_s, unscale, FitOptions, Problem};
use crate::forward::Landing;
use glam::DVec2;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use nlopt::{Algorithm, Nlopt, Target};
use std::cell::RefCell;
use std::time::Instant;

/// One fitted parameter's result.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamResult {
    /// Name as in the manifest.
    pub name: String,
    /// Fitted value.
    pub value: f64,
    /// One-sigma uncertainty from the Jacobian (None when the captures cannot determine it).
    pub sigma: Option<f64>,
    /// Start value.
    pub start: f64,
}

/// The outcome of a fit.
#[derive(Debug, Clone)]
pub struct FitResult {
    /// Per free parameter.
    pub params: Vec<ParamResult>,
    /// Correlation matrix of the free parameters (None entries where undetermined).
    pub correlations: Vec<Vec<Option<f64>>>,
    /// Fitted sub-pixel shift of each capture.
    pub shifts_px: Vec<DVec2>,
    /// Per capture: ‖d − model‖ / ‖d − background‖.
    pub residuals: Vec<f64>,
    /// Objective evaluations of each stage.
    pub evaluations: Vec<(String, usize)>,
    /// (seconds, objective) after each improvement.
    pub history: Vec<(f64, f64)>,
    /// Wall-clock time.
    pub seconds: f64,
    /// The scaled parameter vector at the end.
    pub scaled: Vec<f64>,
}

struct Tracker<'a> {
    problem: &'a Problem,
    start: Instant,
    evaluations: usize,
    best: f64,
    best_x: Vec<f64>,
    history: Vec<(f64, f64)>,
}

impl Tracker<'_> {
    fn eval(&mut self, x: &[f64]) -> f64 {
        let f = self.problem.objective(x);
        self.evaluations += 1;
        if f < self.best {
            self.best = f;
            self.best_x = x.to_vec();
            self.history.push((elapsed_s(self.start), f));
        }
        f
    }
}

/// Global (CRS2) then local (BOBYQA) stage on the scaled parameters, each with its share of
/// the time; returns the best point found.
fn nlopt_stages(
    problem: &Problem,
    x0: &[f64],
    options: &FitOptions,
    start: Instant,
    history: &mut Vec<(f64, f64)>,
    evals: &mut Vec<(String, usize)>,
) -> Vec<f64> {
    let n = x0.len();
    let tracker = RefCell::new(Tracker {
        problem,
        start,
        evaluations: 0,
        best: f64::INFINITY,
        best_x: x0.to_vec(),
        history: std::mem::take(history),
    });
    tracker.borrow_mut().eval(x0);
    let stages: [(Algorithm, f64, &str); 2] =
        [(Algorithm::Crs2Lm, options.global_share, "global (CRS2)"), (Algorithm::Bobyqa, 0.3, "local (BOBYQA)")];
    for (algorithm, share, label) in stages {
        let budget = options.time_limit_s * share;
        if budget <= 0.0 || n == 0 {
            continue;
        }
        let before = tracker.borrow().evaluations;
        let objective = |x: &[f64], _g: Option<&mut [f64]>, _: &mut ()| tracker.borrow_mut().eval(x);
        let mut opt = Nlopt::new(algorithm, n, objective, Target::Minimize, ());
        let _ = opt.set_lower_bounds(&vec![0.0; n]);
        let _ = opt.set_upper_bounds(&vec![1.0; n]);
        let _ = opt.set_maxtime(budget);
        let _ = opt.set_xtol_rel(1e-7);
        if matches!(algorithm, Algorithm::Crs2Lm) {
            let _ = opt.set_population(10 * (n + 1));
        } else {
            let _ = opt.set_initial_step1(0.05);
        }
        let mut x = tracker.borrow().best_x.clone();
        let _ = opt.optimize(&mut x);
        drop(opt);
        let done = tracker.borrow().evaluations - before;
        evals.push((label.to_string(), done));
    }
    let t = tracker.into_inner();
    *history = t.history;
    t.best_x
}

/// The Levenberg–Marquardt problem: scaled parameters then (x, y) shift per capture.
struct LmProblem<'a> {
    problem: &'a Problem,
    x: DVector<f64>,
    landings: Option<Vec<Vec<Landing>>>,
    evaluations: usize,
}

impl LmProblem<'_> {
    fn split(&self, x: &DVector<f64>) -> (Vec<f64>, Vec<DVec2>) {
        let n = self.problem.free.len();
        let scaled: Vec<f64> = x.iter().take(n).map(|v| v.clamp(0.0, 1.0)).collect();
        let shifts = (0..self.problem.captures.len()).map(|c| DVec2::new(x[n + 2 * c], x[n + 2 * c + 1])).collect();
        (scaled, shifts)
    }

    fn landings_at(&self, scaled: &[f64]) -> Option<Vec<Vec<Landing>>> {
        let model = self.problem.model_at(&unscale(&self.problem.free, scaled)).ok()?;
        self.problem.landings(&model)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for LmProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        let n = self.problem.free.len();
        let mut x = x.clone();
        for k in 0..n {
            x[k] = x[k].clamp(0.0, 1.0);
        }
        let (scaled, _) = self.split(&x);
        self.landings = self.landings_at(&scaled);
        self.x = x;
        self.evaluations += 1;
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let (_, shifts) = self.split(&self.x);
        Some(DVector::from_vec(self.problem.residual_vector(self.landings.as_deref(), &shifts)))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        // Forward differences: a parameter re-traces every capture, a shift re-splats its own.
        let base = self.residuals()?;
        let m = base.len();
        let n = self.problem.free.len();
        let cols = self.x.len();
        let mut j = DMatrix::zeros(m, cols);
        let (scaled, shifts) = self.split(&self.x);
        for k in 0..n {
            let h = if scaled[k] > 0.5 { -1e-4 } else { 1e-4 };
            let mut s = scaled.clone();
            s[k] += h;
            let l = self.landings_at(&s);
            let r = self.problem.residual_vector(l.as_deref(), &shifts);
            for i in 0..m {
                j[(i, k)] = (r[i] - base[i]) / h;
            }
        }
        let landings = self.landings.as_ref()?;
        let mut row = 0;
        for (c, p) in self.problem.captures.iter().enumerate() {
            let count = p.image.mask.iter().filter(|v| **v).count() * p.image.channels.len();
            for axis in 0..2 {
                let h = 1e-3;
                let mut sh = shifts[c];
                if axis == 0 {
                    sh.x += h;
                } else {
                    sh.y += h;
                }
                let f = self.problem.fit_capture(c, &landings[c], sh);
                let mut i = row;
                for (ch, model) in f.model.iter().enumerate() {
                    let d = &p.image.channels[ch];
                    for (k, dk) in d.iter().enumerate() {
                        if p.image.mask[k] {
                            j[(i, n + 2 * c + axis)] = ((dk - model[k]) / p.norms[ch] - base[i]) / h;
                            i += 1;
                        }
                    }
                }
            }
            row += count;
        }
        Some(j)
    }
}

/// Runs the fit.
pub fn run(problem: &Problem, options: &FitOptions) -> FitResult {
    let start = Instant::now();
    let n = problem.free.len();
    let x0: Vec<f64> = problem
        .free
        .iter()
        .map(|f| {
            let v = problem.start.get(&f.param).unwrap_or(f.min);
            ((v - f.min) / (f.max - f.min)).clamp(0.0, 1.0)
        })
        .collect();
    let mut history = Vec::new();
    let mut evaluations = Vec::new();
    // 1–2. Global and local stages with centroid-matched shifts.
    let best = nlopt_stages(problem, &x0, options, start, &mut history, &mut evaluations);
    // 3. Levenberg–Marquardt on parameters and shifts together.
    let model = problem.model_at(&unscale(&problem.free, &best)).ok();
    let landings = model.as_ref().and_then(|m| problem.landings(m));
    let shifts = landings
        .as_ref()
        .map(|l| problem.centroid_shifts(l))
        .unwrap_or_else(|| vec![DVec2::ZERO; problem.captures.len()]);
    let mut x = best.clone();
    for s in &shifts {
        x.push(s.x);
        x.push(s.y);
    }
    let mut lm = LmProblem { problem, x: DVector::from_vec(x.clone()), landings: None, evaluations: 0 };
    lm.set_params(&DVector::from_vec(x));
    let (lm, _report) = LevenbergMarquardt::new().with_patience(20).minimize(lm);
    evaluations.push(("Levenberg–Marquardt".to_string(), lm.evaluations));
    let (scaled, shifts) = lm.split(&lm.x);
    let r = lm.residuals().unwrap_or_else(|| DVector::zeros(0));
    let objective = r.norm_squared();
    history.push((elapsed_s(start), objective));
    // 4. Uncertainty: covariance s² (JᵀJ)⁻¹ of the scaled parameters, back to units.
    let jac = lm.jacobian();
    let dof = (r.len() as f64 - lm.x.len() as f64).max(1.0);
    let s2 = objective / dof;
    let mut sigma = vec![None; n];
    let mut correlations = vec![vec![None; n]; n];
    if let Some(j) = jac {
        let jtj = j.transpose() * &j;
        if let Some(cov) = jtj.clone().try_inverse() {
            for a in 0..n {
                let range = problem.free[a].max - problem.free[a].min;
                let var = cov[(a, a)] * s2;
                // a parameter whose 1σ spans more than its whole range is not determined
                let column = j.column(a).norm();
                if var.is_finite() && var >= 0.0 && var.sqrt() < 1.0 && column > 1e-9 {
                    sigma[a] = Some(var.sqrt() * range);
                }
            }
            for a in 0..n {
                for b in 0..n {
                    if sigma[a].is_some() && sigma[b].is_some() {
                        correlations[a][b] = Some(cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt());
                    }
                }
            }
        }
    }
    let values = unscale(&problem.free, &scaled);
    let model = problem.model_at(&values).ok();
    let landings = model.as_ref().and_then(|m| problem.landings(m));
    let residuals = (0..problem.captures.len())
        .map(|c| landings.as_ref().map(|l| problem.fit_capture(c, &l[c], shifts[c]).residual).unwrap_or(1.0))
        .collect();
    let params = problem
        .free
        .iter()
        .enumerate()
        .map(|(k, f)| ParamResult {
            name: f.name.clone(),
            value: values[k],
            sigma: sigma[k],
            start: unscale(&problem.free, &x0)[k],
        })
        .collect();
    FitResult {
        params,
        correlations,
        shifts_px: shifts,
        residuals,
        evaluations,
        history,
        seconds: elapsed_s(start),
        scaled,
    }
}
