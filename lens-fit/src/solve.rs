//! Runs the stages of a fit (see [`crate::fit`]) and gathers what the report needs: values,
//! uncertainties and correlations from the Jacobian, per-capture residuals, the convergence
//! history.

use crate::fit::{elapsed_s, unscale, FitOptions, Problem};
use crate::forward::Landing;
use glam::DVec2;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use nlopt::{Algorithm, Nlopt, Target};
use rayon::prelude::*;
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
    /// Wall-clock seconds of each stage (the same stages; the last is the uncertainty).
    pub stage_seconds: Vec<(String, f64)>,
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
    stage_seconds: &mut Vec<(String, f64)>,
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
    let f0 = tracker.borrow_mut().eval(x0);
    let mut fine_best = (f0, x0.to_vec());
    // the global stage samples the pupil more coarsely (its job is the basin, not the digits)
    let coarse_rays = options.global_rays();
    let coarse = if coarse_rays < problem.pattern.len() {
        Problem { pattern: crate::forward::disc_pattern(coarse_rays), ..problem.clone() }
    } else {
        problem.clone()
    };
    let stages: [(Algorithm, f64, &str); 2] = [
        (Algorithm::Crs2Lm, options.global_share, "global (CRS2)"),
        (Algorithm::Bobyqa, options.local_share, "local (BOBYQA)"),
    ];
    for (algorithm, share, label) in stages {
        let budget = options.time_limit_s * share;
        if budget <= 0.0 || n == 0 {
            continue;
        }
        let before = tracker.borrow().evaluations;
        let stage_start = Instant::now();
        let global = matches!(algorithm, Algorithm::Crs2Lm);
        if global {
            tracker.borrow_mut().problem = &coarse;
            tracker.borrow_mut().best = f64::INFINITY;
        }
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
        if global {
            // back to the fit's own rays: the coarse best counts only if it is better there
            let mut t = tracker.borrow_mut();
            t.problem = problem;
            let coarse_best = t.best_x.clone();
            let f = problem.objective(&coarse_best);
            t.evaluations += 1;
            if f < fine_best.0 {
                fine_best = (f, coarse_best);
                t.history.push((elapsed_s(start), f));
            }
            t.best = fine_best.0;
            t.best_x = fine_best.1.clone();
        }
        let done = tracker.borrow().evaluations - before;
        evals.push((label.to_string(), done));
        stage_seconds.push((label.to_string(), elapsed_s(stage_start)));
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
    /// After the first Jacobian, none is computed past this (the fit's time limit).
    deadline: Option<Instant>,
    jacobians: std::sync::atomic::AtomicUsize,
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
        // past the time limit the minimiser stops at its last accepted point
        if self.jacobians.load(std::sync::atomic::Ordering::Relaxed) > 0
            && self.deadline.is_some_and(|d| Instant::now() > d)
        {
            return None;
        }
        self.jacobians.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        // Forward differences: a parameter re-traces every capture, a shift re-splats its own.
        let base = self.residuals()?;
        let m = base.len();
        let n = self.problem.free.len();
        let cols = self.x.len();
        let mut j = DMatrix::zeros(m, cols);
        let (scaled, shifts) = self.split(&self.x);
        // the parameter columns are independent: in parallel, collected in order
        let columns: Vec<(f64, Vec<f64>)> = (0..n)
            .into_par_iter()
            .map(|k| {
                let h = if scaled[k] > 0.5 { -1e-4 } else { 1e-4 };
                let mut s = scaled.clone();
                s[k] += h;
                let l = self.landings_at(&s);
                (h, self.problem.residual_vector(l.as_deref(), &shifts))
            })
            .collect();
        for (k, (h, r)) in columns.iter().enumerate() {
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
    let mut stage_seconds = Vec::new();
    // 1–2. Global and local stages with centroid-matched shifts.
    let best = nlopt_stages(problem, &x0, options, start, &mut history, &mut evaluations, &mut stage_seconds);
    let lm_start = Instant::now();
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
    let deadline = start + std::time::Duration::from_secs_f64(options.time_limit_s);
    let mut lm = LmProblem {
        problem,
        x: DVector::from_vec(x.clone()),
        landings: None,
        evaluations: 0,
        deadline: Some(deadline),
        jacobians: std::sync::atomic::AtomicUsize::new(0),
    };
    lm.set_params(&DVector::from_vec(x));
    let (mut lm, _report) = LevenbergMarquardt::new().with_patience(20).minimize(lm);
    lm.deadline = None;
    evaluations.push(("Levenberg–Marquardt".to_string(), lm.evaluations));
    stage_seconds.push(("Levenberg–Marquardt".to_string(), elapsed_s(lm_start)));
    let sigma_start = Instant::now();
    let (scaled, shifts) = lm.split(&lm.x);
    let r = lm.residuals().unwrap_or_else(|| DVector::zeros(0));
    let objective = r.norm_squared();
    history.push((elapsed_s(start), objective));
    // 4. Uncertainty: covariance s² (JᵀJ)⁻¹ of the scaled parameters, back to units.
    let jac = lm.jacobian();
    let dof = (r.len() as f64 - lm.x.len() as f64).max(1.0);
    let s2 = objective / dof;
    let (sigma, correlations) = match jac {
        Some(j) => {
            let (scaled_sigma, correlations) = uncertainties(&j, n, s2);
            let sigma = scaled_sigma.iter().zip(&problem.free).map(|(s, f)| s.map(|s| s * (f.max - f.min))).collect();
            (sigma, correlations)
        }
        None => (vec![None; n], vec![vec![None; n]; n]),
    };
    stage_seconds.push(("uncertainty".to_string(), elapsed_s(sigma_start)));
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
        stage_seconds,
        history,
        seconds: elapsed_s(start),
        scaled,
    }
}

/// One-sigma uncertainties (scaled units, the first `n` columns of `j`) and their correlations
/// from `s2 (JᵀJ)⁻¹`. A parameter is undetermined (None) when no residual responds to it (its
/// column is zero, or below 1e-9 of the largest column), when it has a share in a direction
/// the data cannot see (an eigenvector of the equilibrated JᵀJ with an eigenvalue under 1e-12
/// of the largest: a degeneracy with other unknowns), or when its 1σ spans more than its whole
/// range. The other unknowns keep their uncertainties (the covariance is taken over the
/// columns that respond, through the eigen-decomposition, not a plain inverse that a single
/// dead column would make fail for all).
pub fn uncertainties(j: &DMatrix<f64>, n: usize, s2: f64) -> (Vec<Option<f64>>, Vec<Vec<Option<f64>>>) {
    let mut sigma = vec![None; n];
    let mut correlations = vec![vec![None; n]; n];
    let norms: Vec<f64> = (0..j.ncols()).map(|c| j.column(c).norm()).collect();
    let largest = norms.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
    if !(largest > 0.0) || !s2.is_finite() {
        return (sigma, correlations);
    }
    let live: Vec<usize> = (0..j.ncols()).filter(|&c| norms[c].is_finite() && norms[c] > 1e-9 * largest).collect();
    if live.is_empty() {
        return (sigma, correlations);
    }
    // equilibrated normal matrix over the live columns: unit diagonal
    let m = live.len();
    let mut a = DMatrix::zeros(m, m);
    for (p, &cp) in live.iter().enumerate() {
        for (q, &cq) in live.iter().enumerate().skip(p) {
            let v = j.column(cp).dot(&j.column(cq)) / (norms[cp] * norms[cq]);
            a[(p, q)] = v;
            a[(q, p)] = v;
        }
    }
    let eig = nalgebra::SymmetricEigen::new(a);
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let threshold = lmax * 1e-12;
    let mut cov = DMatrix::zeros(m, m);
    let mut blind = vec![0.0; m];
    for k in 0..m {
        let l = eig.eigenvalues[k];
        let v = eig.eigenvectors.column(k);
        if l > threshold {
            cov += v * v.transpose() / l;
        } else {
            for p in 0..m {
                blind[p] += v[p] * v[p];
            }
        }
    }
    let index: Vec<Option<usize>> = (0..n).map(|c| live.iter().position(|&l| l == c)).collect();
    for a in 0..n {
        let Some(p) = index[a] else { continue };
        if blind[p] > 1e-6 {
            continue;
        }
        let var = cov[(p, p)] * s2 / (norms[a] * norms[a]);
        // a parameter whose 1σ spans more than its whole range is not determined
        if var.is_finite() && var >= 0.0 && var.sqrt() < 1.0 {
            sigma[a] = Some(var.sqrt());
        }
    }
    for a in 0..n {
        for b in 0..n {
            if let (Some(p), Some(q), Some(_), Some(_)) = (index[a], index[b], sigma[a], sigma[b]) {
                correlations[a][b] = Some(cov[(p, q)] / (cov[(p, p)] * cov[(q, q)]).sqrt());
            }
        }
    }
    (sigma, correlations)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jacobian(cols: &[Vec<f64>]) -> DMatrix<f64> {
        DMatrix::from_fn(cols[0].len(), cols.len(), |i, c| cols[c][i])
    }

    #[test]
    fn a_dead_column_is_undetermined_and_the_others_keep_their_sigma() {
        let rows = 50;
        let a: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.37).sin()).collect();
        let b: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.11).cos()).collect();
        let zero = vec![0.0; rows];
        let (s, c) = uncertainties(&jacobian(&[a.clone(), zero.clone(), b.clone()]), 3, 1e-4);
        assert!(s[0].is_some() && s[2].is_some(), "{s:?}");
        assert_eq!(s[1], None);
        assert_eq!(c[1][0], None);
        assert!((c[0][0].unwrap() - 1.0).abs() < 1e-12);
        // the same sigmas as without the dead column
        let (s2, _) = uncertainties(&jacobian(&[a.clone(), b.clone()]), 2, 1e-4);
        assert!((s[0].unwrap() - s2[0].unwrap()).abs() < 1e-12 * s2[0].unwrap());
        // a column of round-off next to real ones is dead too, never a tiny sigma
        let tiny: Vec<f64> = (0..rows).map(|i| 1e-14 * (i as f64).sin()).collect();
        let (s, _) = uncertainties(&jacobian(&[a.clone(), tiny, b.clone()]), 3, 1e-4);
        assert_eq!(s[1], None);
        // two identical columns (a degeneracy): both undetermined, the third not
        let (s, _) = uncertainties(&jacobian(&[a.clone(), a.clone(), b.clone()]), 3, 1e-4);
        assert_eq!((s[0], s[1]), (None, None));
        assert!(s[2].is_some());
        // all zero: nothing determined
        let (s, _) = uncertainties(&jacobian(&[zero.clone(), zero]), 2, 1e-4);
        assert_eq!(s, vec![None, None]);
    }
}
