//! Runs the stages of a fit (see [`crate::fit`]) and gathers what the report needs: values,
//! uncertainties and correlations from the Jacobian, per-capture residuals, the convergence
//! history.

use crate::fit::{elapsed_s, unscale, FitOptions, Problem, StopFlag};
use crate::forward::Landing;
use glam::DVec2;
use nalgebra::{DMatrix, DVector};
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
    /// Why Levenberg–Marquardt stopped (`ftol`, `xtol`, `gtol`, `patience`, `evaluation
    /// budget`, `time limit`, `singular`, `interrupted`) and its iterations (Jacobians).
    pub lm_stop: (&'static str, usize),
    /// The Levenberg–Marquardt iteration from which its Jacobians were central differences
    /// (0: from the start, as asked; None: forward differences throughout).
    pub lm_central_from: Option<usize>,
    /// Whether the uncertainties were computed (false only for an interrupted fit whose end
    /// point had no Jacobian yet).
    pub uncertainties_computed: bool,
}

/// What the progress callback sees after each evaluation.
#[derive(Debug, Clone, Copy)]
pub struct Progress<'a> {
    /// The stage running.
    pub stage: &'a str,
    /// Objective evaluations so far (the whole fit; a Jacobian counts one per parameter).
    pub evaluations: usize,
    /// The evaluation budget (`FitOptions::max_evaluations`), if any.
    pub budget: Option<usize>,
    /// Best objective so far (Σ r²; the global stage's at its coarser rays).
    pub best: f64,
    /// Seconds since the fit began.
    pub elapsed_s: f64,
}

/// A progress callback (called on the fit's own thread).
pub type ProgressFn<'a> = &'a (dyn Fn(&Progress) + Sync);

/// Two local starts are distinct when their scaled distance (rms over the coordinates, each in
/// [0, 1] over its bounds) is over this.
pub const MIN_START_DISTANCE: f64 = 0.05;

/// Seed of NLopt's random numbers (CRS2), set before every global stage: the same fit gives
/// the same points.
const NLOPT_SEED: u64 = 20_261_201;

/// Evaluation budgets of the three stages from `FitOptions::max_evaluations` (None: unbounded).
fn stage_budgets(options: &FitOptions) -> [Option<usize>; 3] {
    if options.max_evaluations == 0 {
        return [None; 3];
    }
    let total = options.max_evaluations;
    let global = (total as f64 * options.global_share.max(0.0)).round() as usize;
    let local = (total as f64 * options.local_share.max(0.0)).round() as usize;
    let lm = total.saturating_sub(global + local);
    [Some(global.min(total)), Some(local.min(total - global.min(total))), Some(lm)]
}

/// One capture's residuals (as in [`Problem::residual_vector`]) at a shift.
fn capture_residuals(problem: &Problem, c: usize, landing: &[Landing], shift: DVec2) -> Vec<f64> {
    let p = &problem.captures[c];
    let f = problem.fit_capture(c, landing, shift);
    let mut r = Vec::new();
    for (ch, model) in f.model.iter().enumerate() {
        for (k, dk) in p.image.channels[ch].iter().enumerate() {
            if p.image.mask[k] {
                r.push((dk - model[k]) / p.norms[ch]);
            }
        }
    }
    r
}

/// Gauss–Newton steps on one capture's (x, y) shift alone, from `shift` (the landing is fixed:
/// each step re-splats, nothing is re-traced); returns the shift and its Σr².
pub fn matched_shift(problem: &Problem, c: usize, landing: &[Landing], shift: DVec2, steps: usize) -> (DVec2, f64) {
    let sq = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let mut s = shift;
    let mut r = capture_residuals(problem, c, landing, s);
    let mut rr = sq(&r);
    let h = 1e-3;
    for _ in 0..steps {
        let rx = capture_residuals(problem, c, landing, s + DVec2::new(h, 0.0));
        let ry = capture_residuals(problem, c, landing, s + DVec2::new(0.0, h));
        let (mut a11, mut a12, mut a22, mut g1, mut g2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for i in 0..r.len() {
            let (jx, jy) = ((rx[i] - r[i]) / h, (ry[i] - r[i]) / h);
            a11 += jx * jx;
            a12 += jx * jy;
            a22 += jy * jy;
            g1 += jx * r[i];
            g2 += jy * r[i];
        }
        // a little damping keeps the 2 × 2 step sane on a flat or one-dimensional spot
        let (a11, a22) = (a11 * 1.001 + 1e-12, a22 * 1.001 + 1e-12);
        let det = a11 * a22 - a12 * a12;
        if !(det > 0.0) {
            break;
        }
        let mut step = DVec2::new(-(a22 * g1 - a12 * g2) / det, -(a11 * g2 - a12 * g1) / det);
        if step.length() > 2.0 {
            step *= 2.0 / step.length();
        }
        let mut improved = false;
        for _ in 0..3 {
            let rn = capture_residuals(problem, c, landing, s + step);
            let rrn = sq(&rn);
            if rrn < rr {
                s += step;
                r = rn;
                rr = rrn;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved || step.length() < 1e-3 {
            break;
        }
    }
    (s, rr)
}

/// The objective of the global and local stages: Σ r² with each capture's shift matched to it
/// (from the centroid-matching shift, [`matched_shift`]); captures in parallel, summed in order.
/// The matched shifts are returned too.
pub fn profiled_objective(problem: &Problem, scaled: &[f64], steps: usize) -> (f64, Option<Vec<DVec2>>) {
    let failed = problem.captures.len() as f64 * 4.0;
    let Ok(model) = problem.model_at(&unscale(&problem.free, scaled)) else { return (failed, None) };
    let Some(landings) = problem.landings(&model) else { return (failed, None) };
    let start = problem.centroid_shifts(&landings);
    let matched: Vec<(DVec2, f64)> = (0..problem.captures.len())
        .into_par_iter()
        .map(|c| matched_shift(problem, c, &landings[c], start[c], steps))
        .collect();
    (matched.iter().map(|m| m.1).sum(), Some(matched.iter().map(|m| m.0).collect()))
}

struct Tracker<'a> {
    problem: &'a Problem,
    start: Instant,
    /// Evaluations of the whole fit.
    evaluations: usize,
    best: f64,
    best_x: Vec<f64>,
    history: Vec<(f64, f64)>,
    /// Every point of the global stage with its (coarse) objective, when recording.
    record: Option<Vec<(f64, Vec<f64>)>>,
    stage: &'static str,
    budget: Option<usize>,
    progress: ProgressFn<'a>,
    /// No evaluation past this count (the stage's budget): NLopt's CRS2 checks its `maxeval`
    /// only between trials of several evaluations, so it is enforced here; the calls past it
    /// return +∞ without tracing.
    cap: usize,
    shift_steps: usize,
    stop: StopFlag,
}

/// What [`Tracker::eval`] returns once a stop is requested: below NLopt's `stopval`
/// ([`STOP_BELOW`]; objectives are sums of squares, never negative), so the optimiser ends at once.
const STOPPED_VALUE: f64 = -1.0;
/// NLopt's `stopval` for the global and local stages.
const STOP_BELOW: f64 = -0.5;

impl Tracker<'_> {
    fn eval(&mut self, x: &[f64]) -> f64 {
        if self.stop.requested() {
            return STOPPED_VALUE;
        }
        if self.evaluations >= self.cap {
            return f64::INFINITY;
        }
        let f = profiled_objective(self.problem, x, self.shift_steps).0;
        self.evaluations += 1;
        if let Some(r) = &mut self.record {
            r.push((f, x.to_vec()));
        }
        if f < self.best {
            self.best = f;
            self.best_x = x.to_vec();
            self.history.push((elapsed_s(self.start), f));
        }
        self.report();
        f
    }

    fn report(&self) {
        (self.progress)(&Progress {
            stage: self.stage,
            evaluations: self.evaluations,
            budget: self.budget,
            best: self.best,
            elapsed_s: elapsed_s(self.start),
        });
    }
}

/// The `k` best points of `points` (objective, scaled x) that are mutually distinct (scaled
/// rms distance over [`MIN_START_DISTANCE`]), best first; ties keep the order of evaluation.
pub fn distinct_best(points: &[(f64, Vec<f64>)], k: usize) -> Vec<(f64, Vec<f64>)> {
    let mut order: Vec<usize> = (0..points.len()).filter(|&i| points[i].0.is_finite()).collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0).then(a.cmp(&b)));
    let mut chosen: Vec<(f64, Vec<f64>)> = Vec::new();
    for i in order {
        if chosen.len() >= k {
            break;
        }
        let x = &points[i].1;
        let far = chosen.iter().all(|(_, y)| {
            let d2: f64 = x.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum();
            (d2 / x.len().max(1) as f64).sqrt() > MIN_START_DISTANCE
        });
        if far {
            chosen.push(points[i].clone());
        }
    }
    chosen
}

/// Global (CRS2, coarse rays) then local (BOBYQA from the `options.starts` best distinct global
/// points, sharing the stage's time and evaluations) on the scaled parameters; returns the best
/// point found at the local stage's rays.
#[allow(clippy::too_many_arguments)]
fn nlopt_stages(
    problem: &Problem,
    x0: &[f64],
    options: &FitOptions,
    start: Instant,
    progress: ProgressFn,
    history: &mut Vec<(f64, f64)>,
    evals: &mut Vec<(String, usize)>,
    stage_seconds: &mut Vec<(String, f64)>,
) -> (Vec<f64>, usize) {
    let n = x0.len();
    let budgets = stage_budgets(options);
    let total_budget = (options.max_evaluations > 0).then_some(options.max_evaluations);
    let with_rays = |rays: usize| {
        if rays < problem.pattern.rays() {
            Problem { pattern: crate::forward::Pattern::for_fit(rays, options.subsamples), ..problem.clone() }
        } else {
            problem.clone()
        }
    };
    let mut coarse = with_rays(options.global_rays());
    if options.global_footprint_px > 0.0 {
        // coarse to fine: the global stage sees every spot blurred (a smoother landscape)
        coarse.footprint_px = options.global_footprint_px;
    }
    let local = with_rays(if options.local_rays > 0 { options.local_rays } else { options.rays });
    let mut t = Tracker {
        problem,
        start,
        evaluations: 0,
        best: f64::INFINITY,
        best_x: x0.to_vec(),
        history: std::mem::take(history),
        record: None,
        stage: "start",
        budget: total_budget,
        progress,
        cap: usize::MAX,
        shift_steps: options.shift_steps,
        stop: options.stop,
    };
    if n == 0 {
        *history = t.history;
        return (t.best_x, t.evaluations);
    }
    // 1. Global: CRS2 on the coarse problem; every point is recorded for the local starts.
    let global_time = options.time_limit_s * options.global_share;
    let global_evals = budgets[0].unwrap_or(usize::MAX);
    let mut candidates: Vec<(f64, Vec<f64>)> = Vec::new();
    if global_time > 0.0 && global_evals >= 2 {
        let before = t.evaluations;
        let stage_start = Instant::now();
        t.problem = &coarse;
        t.stage = "global (CRS2)";
        t.record = Some(Vec::new());
        t.cap = budgets[0].map_or(usize::MAX, |b| before + b);
        t.eval(x0);
        {
            let cell = RefCell::new(&mut t);
            let objective = |x: &[f64], _g: Option<&mut [f64]>, _: &mut ()| cell.borrow_mut().eval(x);
            let mut opt = Nlopt::new(Algorithm::Crs2Lm, n, objective, Target::Minimize, ());
            Nlopt::<fn(&[f64], Option<&mut [f64]>, &mut ()) -> f64, ()>::srand_seed(Some(NLOPT_SEED));
            let _ = opt.set_lower_bounds(&vec![0.0; n]);
            let _ = opt.set_upper_bounds(&vec![1.0; n]);
            let _ = opt.set_maxtime(global_time);
            if let Some(b) = budgets[0] {
                let _ = opt.set_maxeval((b - 1).min(u32::MAX as usize) as u32);
            }
            let _ = opt.set_xtol_rel(1e-7);
            let _ = opt.set_stopval(STOP_BELOW);
            let _ = opt.set_population(10 * (n + 1));
            let mut x = x0.to_vec();
            let _ = opt.optimize(&mut x);
        }
        candidates = distinct_best(t.record.as_deref().unwrap_or(&[]), options.starts.max(1));
        t.record = None;
        t.cap = usize::MAX;
        t.problem = &local;
        evals.push(("global (CRS2)".to_string(), t.evaluations - before));
        stage_seconds.push(("global (CRS2)".to_string(), elapsed_s(stage_start)));
    }
    if candidates.is_empty() {
        candidates.push((f64::NAN, x0.to_vec()));
    }
    // 2. Local: BOBYQA from each candidate at the local stage's rays; the best end point wins.
    t.best = f64::INFINITY;
    t.problem = &local;
    let local_time = options.time_limit_s * options.local_share;
    let before = t.evaluations;
    let stage_start = Instant::now();
    let mut local_left = budgets[1];
    if local_time > 0.0 && local_left.is_none_or(|b| b > 0) {
        t.stage = "local (BOBYQA)";
        let deadline = stage_start + std::time::Duration::from_secs_f64(local_time);
        let k = candidates.len();
        for (i, (_, c)) in candidates.iter().enumerate() {
            let starts_left = (k - i) as f64;
            let time_left = deadline.saturating_duration_since(Instant::now()).as_secs_f64();
            let evals_here = local_left.map(|b| (b as f64 / starts_left).floor() as usize);
            if time_left <= 0.0 || evals_here == Some(0) || options.stop.requested() {
                continue;
            }
            let used_before = t.evaluations;
            t.cap = evals_here.map_or(usize::MAX, |e| used_before + e);
            {
                let cell = RefCell::new(&mut t);
                let objective = |x: &[f64], _g: Option<&mut [f64]>, _: &mut ()| cell.borrow_mut().eval(x);
                let mut opt = Nlopt::new(Algorithm::Bobyqa, n, objective, Target::Minimize, ());
                let _ = opt.set_lower_bounds(&vec![0.0; n]);
                let _ = opt.set_upper_bounds(&vec![1.0; n]);
                let _ = opt.set_maxtime(time_left / starts_left);
                if let Some(e) = evals_here {
                    let _ = opt.set_maxeval(e.min(u32::MAX as usize) as u32);
                }
                let _ = opt.set_xtol_rel(1e-7);
                let _ = opt.set_stopval(STOP_BELOW);
                let _ = opt.set_initial_step1(0.05);
                let mut x = c.clone();
                let _ = opt.optimize(&mut x);
            }
            if let Some(b) = &mut local_left {
                *b = b.saturating_sub(t.evaluations - used_before);
            }
        }
        t.cap = usize::MAX;
    } else {
        // no local stage: the best candidate counts only if it is better at the local stage's rays
        t.eval(x0);
        if candidates[0].1 != x0 {
            t.eval(&candidates[0].1.clone());
        }
    }
    evals.push(("local (BOBYQA)".to_string(), t.evaluations - before));
    stage_seconds.push(("local (BOBYQA)".to_string(), elapsed_s(stage_start)));
    *history = t.history;
    (t.best_x, t.evaluations)
}

/// A column of the Jacobian: its nonzero rows `offset..offset + values.len()`.
struct Column {
    offset: usize,
    values: Vec<f64>,
}

impl Column {
    fn dot(&self, other: &Column) -> f64 {
        let lo = self.offset.max(other.offset);
        let hi = (self.offset + self.values.len()).min(other.offset + other.values.len());
        if hi <= lo {
            return 0.0;
        }
        let a = &self.values[lo - self.offset..hi - self.offset];
        let b = &other.values[lo - other.offset..hi - other.offset];
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    fn dot_dense(&self, r: &[f64]) -> f64 {
        self.values.iter().zip(&r[self.offset..]).map(|(x, y)| x * y).sum()
    }
}

/// JᵀJ and Jᵀr from the columns: every entry is a dot product summed in row order, the
/// entries computed in parallel (so the result does not depend on the thread count).
fn normal_equations(cols: &[Column], r: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
    let u = cols.len();
    let pairs: Vec<(usize, usize)> = (0..u).flat_map(|p| (p..u).map(move |q| (p, q))).collect();
    let dots: Vec<f64> = pairs.par_iter().map(|&(p, q)| cols[p].dot(&cols[q])).collect();
    let mut a = DMatrix::zeros(u, u);
    for (&(p, q), v) in pairs.iter().zip(dots) {
        a[(p, q)] = v;
        a[(q, p)] = v;
    }
    let g: Vec<f64> = cols.par_iter().map(|c| c.dot_dense(r)).collect();
    (a, DVector::from_vec(g))
}

/// The Levenberg–Marquardt unknowns: scaled parameters then (x, y) shift per capture.
struct LmProblem<'a> {
    problem: &'a Problem,
    /// Residual rows of each capture (`offset`, `count`).
    rows: Vec<(usize, usize)>,
    /// Central differences for the parameter columns (two evaluations per parameter).
    central: bool,
}

impl LmProblem<'_> {
    fn new(problem: &Problem, central: bool) -> LmProblem<'_> {
        let mut rows = Vec::new();
        let mut offset = 0;
        for p in &problem.captures {
            let count = p.image.mask.iter().filter(|v| **v).count() * p.image.channels.len();
            rows.push((offset, count));
            offset += count;
        }
        LmProblem { problem, rows, central }
    }

    /// Evaluations one Jacobian costs.
    fn jacobian_cost(&self, central: bool) -> usize {
        self.problem.free.len() * if central { 2 } else { 1 }
    }

    fn split(&self, x: &[f64]) -> (Vec<f64>, Vec<DVec2>) {
        let n = self.problem.free.len();
        let scaled: Vec<f64> = x.iter().take(n).map(|v| v.clamp(0.0, 1.0)).collect();
        let shifts = (0..self.problem.captures.len()).map(|c| DVec2::new(x[n + 2 * c], x[n + 2 * c + 1])).collect();
        (scaled, shifts)
    }

    fn landings_at(&self, scaled: &[f64]) -> Option<Vec<Vec<Landing>>> {
        let model = self.problem.model_at(&unscale(&self.problem.free, scaled)).ok()?;
        self.problem.landings(&model)
    }

    /// Residuals at `x` (one evaluation) and the landings they came from.
    fn residuals(&self, x: &[f64]) -> (Vec<f64>, Option<Vec<Vec<Landing>>>) {
        let (scaled, shifts) = self.split(x);
        let landings = self.landings_at(&scaled);
        (self.problem.residual_vector(landings.as_deref(), &shifts), landings)
    }

    /// Forward-difference Jacobian at `x` (residuals `base`, landings `landings`; central
    /// differences in the parameters with `central`): a parameter column re-traces every
    /// capture (one evaluation each, in parallel over the parameters), a shift column re-splats
    /// only its own capture (its rows alone are nonzero).
    fn jacobian(&self, x: &[f64], base: &[f64], landings: Option<&[Vec<Landing>]>, central: bool) -> Vec<Column> {
        let n = self.problem.free.len();
        let (scaled, shifts) = self.split(x);
        let mut cols: Vec<Column> = (0..n)
            .into_par_iter()
            .map(|k| {
                let h = if scaled[k] > 0.5 { -1e-4 } else { 1e-4 };
                let mut s = scaled.clone();
                s[k] += h;
                let l = self.landings_at(&s);
                let r = self.problem.residual_vector(l.as_deref(), &shifts);
                if central {
                    // central: the forward step's curvature error cancels (a narrow valley); at
                    // a bound the back point stays on it (a one-sided difference there)
                    s[k] = (scaled[k] - h).clamp(0.0, 1.0);
                    let span = scaled[k] + h - s[k];
                    let l = self.landings_at(&s);
                    let back = self.problem.residual_vector(l.as_deref(), &shifts);
                    let values = r.iter().zip(&back).map(|(a, b)| (a - b) / span).collect();
                    return Column { offset: 0, values };
                }
                Column { offset: 0, values: r.iter().zip(base).map(|(a, b)| (a - b) / h).collect() }
            })
            .collect();
        let shift_cols: Vec<[Column; 2]> = (0..self.problem.captures.len())
            .into_par_iter()
            .map(|c| {
                let (offset, count) = self.rows[c];
                let p = &self.problem.captures[c];
                [0, 1].map(|axis| {
                    let Some(l) = landings else { return Column { offset, values: vec![0.0; count] } };
                    let h = 1e-3;
                    let mut sh = shifts[c];
                    if axis == 0 {
                        sh.x += h;
                    } else {
                        sh.y += h;
                    }
                    let f = self.problem.fit_capture(c, &l[c], sh);
                    let mut values = Vec::with_capacity(count);
                    for (ch, model) in f.model.iter().enumerate() {
                        for (k, dk) in p.image.channels[ch].iter().enumerate() {
                            if p.image.mask[k] {
                                let i = offset + values.len();
                                values.push(((dk - model[k]) / p.norms[ch] - base[i]) / h);
                            }
                        }
                    }
                    Column { offset, values }
                })
            })
            .collect();
        for pair in shift_cols {
            cols.extend(pair);
        }
        cols
    }
}

/// Levenberg–Marquardt's stopping tests, as the `levenberg-marquardt` crate's defaults
/// (MINPACK's tests with 30 ε) and its patience of 20 × (unknowns + 1) residual evaluations.
const LM_TOL: f64 = 30.0 * f64::EPSILON;
const LM_PATIENCE: usize = 20;

/// The end of Levenberg–Marquardt: where, and the normal equations there (if computed at the
/// end point).
struct LmOutcome {
    x: Vec<f64>,
    r: Vec<f64>,
    normal: Option<(DMatrix<f64>, DVector<f64>)>,
    evaluations: usize,
    iterations: usize,
    stop: &'static str,
    /// The iteration from which the Jacobian was taken with central differences (forward
    /// differences first, unless the fit asked for central ones from the start).
    central_from: Option<usize>,
}

/// Poor steps (a gain ratio, actual over predicted decrease of Σr², under
/// [`LM_POOR_GAIN`]), after which the forward-difference Jacobian is taken to be wrong and
/// Levenberg–Marquardt goes on with central differences.
const LM_POOR_STEPS: usize = 2;

/// A gain ratio under which a step counts as poor.
const LM_POOR_GAIN: f64 = 0.1;

/// Marquardt's damped Gauss–Newton on the normal equations: `(JᵀJ + λ D²) δ = −Jᵀr` with D²
/// the largest diagonal of JᵀJ seen so far (MINPACK's scaling), λ adapted from the gain ratio
/// (Nielsen's rule); the parameters are kept in their bounds by clamping the step. Stops on
/// the crate's tests (ftol, xtol, gtol, patience), the evaluation budget (a Jacobian costs one
/// evaluation per parameter, two with central differences) or the deadline: no Jacobian or
/// step that would leave less time than one more Jacobian (the uncertainty stage's) before it,
/// at the times measured so far.
/// Forward differences switch to central ones for good after [`LM_POOR_STEPS`] poor steps
/// (the linear model promising ten times the decrease that came, or a rise): in a narrow,
/// curved valley the forward step's curvature error outweighs the gradient, and no damping
/// mends a gradient of the wrong sign.
#[allow(clippy::too_many_arguments)]
fn levenberg_marquardt(
    lm: &LmProblem,
    x0: Vec<f64>,
    budget: Option<usize>,
    deadline: Instant,
    start: Instant,
    evaluations_before: usize,
    total_budget: Option<usize>,
    progress: ProgressFn,
    history: &mut Vec<(f64, f64)>,
    stop_flag: StopFlag,
) -> LmOutcome {
    let n = lm.problem.free.len();
    let u = x0.len();
    let max_fev = LM_PATIENCE * (u + 1);
    let mut evaluations = 0usize;
    let mut residual_evals = 0usize;
    let mut x = x0;
    let t0 = Instant::now();
    let (mut r, mut landings) = lm.residuals(&x);
    // seconds per residual evaluation, and per evaluation inside a Jacobian (measured)
    let eval_s = t0.elapsed().as_secs_f64();
    let mut jacobian_eval_s = eval_s;
    // whether `seconds` of work still end before the deadline (no estimate: yes)
    let time_for = |seconds: f64| {
        let need = std::time::Duration::try_from_secs_f64(seconds).unwrap_or_default();
        Instant::now().checked_add(need).is_none_or(|end| end <= deadline)
    };
    evaluations += 1;
    residual_evals += 1;
    let mut rr: f64 = r.iter().map(|v| v * v).sum();
    let report = |evaluations: usize, best: f64| {
        progress(&Progress {
            stage: "Levenberg–Marquardt",
            evaluations: evaluations_before + evaluations,
            budget: total_budget,
            best,
            elapsed_s: elapsed_s(start),
        })
    };
    report(evaluations, rr);
    let mut d2 = vec![0.0f64; u];
    let mut lambda = 1e-3;
    let mut nu = 2.0;
    let mut normal: Option<(DMatrix<f64>, DVector<f64>)> = None;
    let mut iterations = 0;
    let mut central_from = lm.central.then_some(0);
    let mut poor_steps = 0;
    // PETZVAL_FIT_TRACE=1 prints every step on stderr
    let trace = std::env::var_os("PETZVAL_FIT_TRACE").is_some_and(|v| v == "1");
    let affordable = |evaluations: usize, cost: usize| budget.is_none_or(|b| evaluations + cost <= b);
    let stop = 'outer: loop {
        if stop_flag.requested() {
            break 'outer "interrupted";
        }
        if normal.is_none() {
            // a new Jacobian at x
            let central = central_from.is_some();
            if !affordable(evaluations, lm.jacobian_cost(central) + 1) {
                break 'outer "evaluation budget";
            }
            // this Jacobian, a step, and the uncertainty stage's Jacobian
            let jac = jacobian_eval_s * lm.jacobian_cost(central) as f64;
            if !time_for(2.0 * jac + eval_s) {
                break 'outer "time limit";
            }
            let tj = Instant::now();
            let cols = lm.jacobian(&x, &r, landings.as_deref(), central);
            jacobian_eval_s = tj.elapsed().as_secs_f64() / lm.jacobian_cost(central).max(1) as f64;
            evaluations += lm.jacobian_cost(central);
            normal = Some(normal_equations(&cols, &r));
            report(evaluations, rr);
        }
        let (a, g) = normal.clone().expect("normal equations");
        iterations += 1;
        // gtol: the gradient orthogonal to every column
        let rnorm = rr.sqrt();
        let gnorm =
            (0..u).filter(|&i| a[(i, i)] > 0.0).map(|i| g[i].abs() / (a[(i, i)].sqrt() * rnorm)).fold(0.0, f64::max);
        if !(gnorm > LM_TOL) {
            break 'outer "gtol";
        }
        for i in 0..u {
            d2[i] = d2[i].max(a[(i, i)]);
            if !(d2[i] > 0.0) {
                d2[i] = 1.0;
            }
        }
        // inner loop: damped steps until one is accepted
        loop {
            if stop_flag.requested() {
                break 'outer "interrupted";
            }
            if !affordable(evaluations, 1) {
                break 'outer "evaluation budget";
            }
            if residual_evals >= max_fev {
                break 'outer "patience";
            }
            let central = central_from.is_some();
            if !time_for(eval_s + jacobian_eval_s * lm.jacobian_cost(central) as f64) {
                break 'outer "time limit";
            }
            let mut m = a.clone();
            for i in 0..u {
                m[(i, i)] += lambda * d2[i];
            }
            let Some(chol) = nalgebra::Cholesky::new(m) else {
                lambda *= nu;
                nu *= 2.0;
                if !lambda.is_finite() {
                    break 'outer "singular";
                }
                continue;
            };
            let step = chol.solve(&(-&g));
            let mut x_new = x.clone();
            for i in 0..u {
                x_new[i] += step[i];
                if i < n {
                    x_new[i] = x_new[i].clamp(0.0, 1.0);
                }
            }
            let delta = DVector::from_iterator(u, (0..u).map(|i| x_new[i] - x[i]));
            // predicted relative reduction of Σr² from the linear model, actual from a trace
            let predicted = -(2.0 * g.dot(&delta) + (&a * &delta).dot(&delta)) / rr;
            let (r_new, l_new) = lm.residuals(&x_new);
            evaluations += 1;
            residual_evals += 1;
            let rr_new: f64 = r_new.iter().map(|v| v * v).sum();
            let actual = if rr_new.is_finite() { 1.0 - rr_new / rr } else { -1.0 };
            let ratio = if predicted > 0.0 { actual / predicted } else { 0.0 };
            let dx = (0..u).map(|i| d2[i] * delta[i] * delta[i]).sum::<f64>().sqrt();
            let xn = (0..u).map(|i| d2[i] * x[i] * x[i]).sum::<f64>().sqrt();
            let accepted = ratio > 1e-4;
            if accepted {
                x = x_new;
                r = r_new;
                landings = l_new;
                rr = rr_new;
                normal = None;
                history.push((elapsed_s(start), rr));
                lambda *= (1.0f64 / 3.0).max(1.0 - (2.0 * ratio - 1.0).powi(3));
                nu = 2.0;
            } else {
                lambda *= nu;
                nu *= 2.0;
            }
            report(evaluations, rr);
            if trace {
                eprintln!(
                    "LM {iterations}: Σr² {rr_new:.6e} (from {:.6e}) predicted {predicted:.3e} actual {actual:.3e} λ {lambda:.2e} {}",
                    if accepted { rr_new } else { rr },
                    if accepted { "accepted" } else { "rejected" }
                );
            }
            if actual.abs() <= LM_TOL && predicted <= LM_TOL && ratio <= 2.0 {
                break 'outer "ftol";
            }
            if dx <= LM_TOL * xn {
                break 'outer "xtol";
            }
            // descents the model promised and that did not come: the slope is wrong
            if predicted > 0.0 && ratio < LM_POOR_GAIN {
                poor_steps += 1;
            }
            if poor_steps >= LM_POOR_STEPS && central_from.is_none() {
                central_from = Some(iterations);
                normal = None;
                if trace {
                    eprintln!(
                        "LM {iterations}: the forward-difference slope is poor here: central differences from now on"
                    );
                }
                break;
            }
            if accepted {
                break;
            }
        }
    };
    LmOutcome { x, r, normal, evaluations, iterations, stop, central_from }
}

/// Runs the fit.
pub fn run(problem: &Problem, options: &FitOptions) -> FitResult {
    run_with_progress(problem, options, &|_| {})
}

/// Runs the fit, calling `progress` after every evaluation.
pub fn run_with_progress(problem: &Problem, options: &FitOptions, progress: ProgressFn) -> FitResult {
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
    let (best, used) =
        nlopt_stages(problem, &x0, options, start, progress, &mut history, &mut evaluations, &mut stage_seconds);
    let lm_start = Instant::now();
    // 3. Levenberg–Marquardt on parameters and shifts together; its budget is what the
    // earlier stages left of the whole (they may stop early).
    let shifts = profiled_objective(problem, &best, options.shift_steps)
        .1
        .unwrap_or_else(|| vec![DVec2::ZERO; problem.captures.len()]);
    let mut x = best.clone();
    for s in &shifts {
        x.push(s.x);
        x.push(s.y);
    }
    let deadline = start + std::time::Duration::from_secs_f64(options.time_limit_s);
    let lm = LmProblem::new(problem, options.central_differences);
    let lm_budget = (options.max_evaluations > 0).then(|| stage_budgets(options)[2].unwrap_or(0));
    let total_budget = (options.max_evaluations > 0).then_some(options.max_evaluations);
    let outcome = levenberg_marquardt(
        &lm,
        x,
        lm_budget,
        deadline,
        start,
        used,
        total_budget,
        progress,
        &mut history,
        options.stop,
    );
    evaluations.push(("Levenberg–Marquardt".to_string(), outcome.evaluations));
    stage_seconds.push(("Levenberg–Marquardt".to_string(), elapsed_s(lm_start)));
    let sigma_start = Instant::now();
    let (scaled, shifts) = lm.split(&outcome.x);
    let objective: f64 = outcome.r.iter().map(|v| v * v).sum();
    history.push((elapsed_s(start), objective));
    // 4. Uncertainty: covariance s² (JᵀJ)⁻¹ of the scaled parameters, back to units (the last
    // Jacobian if it was taken at the end point, else a new one).
    // An interrupted fit takes no new Jacobian: its uncertainties stay unknown.
    let uncertainties_computed = outcome.normal.is_some() || outcome.stop != "interrupted";
    let (a, extra) = match outcome.normal {
        Some((a, _)) => (a, 0),
        None if !uncertainties_computed => (DMatrix::zeros(outcome.x.len(), outcome.x.len()), 0),
        None => {
            let (_, landings) = lm.residuals(&outcome.x);
            let central = outcome.central_from.is_some();
            let cols = lm.jacobian(&outcome.x, &outcome.r, landings.as_deref(), central);
            (normal_equations(&cols, &outcome.r).0, lm.jacobian_cost(central) + 1)
        }
    };
    evaluations.push(("uncertainty".to_string(), extra));
    let dof = (outcome.r.len() as f64 - outcome.x.len() as f64).max(1.0);
    let s2 = objective / dof;
    let (scaled_sigma, correlations) = uncertainties_from_normal(&a, n, s2);
    let sigma: Vec<Option<f64>> =
        scaled_sigma.iter().zip(&problem.free).map(|(s, f)| s.map(|s| s * (f.max - f.min))).collect();
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
        lm_stop: (outcome.stop, outcome.iterations),
        lm_central_from: outcome.central_from,
        uncertainties_computed,
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
    uncertainties_from_normal(&(j.transpose() * j), n, s2)
}

/// [`uncertainties`] from the normal matrix JᵀJ (the column norms are the square roots of
/// its diagonal).
pub fn uncertainties_from_normal(jtj: &DMatrix<f64>, n: usize, s2: f64) -> (Vec<Option<f64>>, Vec<Vec<Option<f64>>>) {
    let mut sigma = vec![None; n];
    let mut correlations = vec![vec![None; n]; n];
    let cols = jtj.ncols();
    let norms: Vec<f64> = (0..cols).map(|c| jtj[(c, c)].max(0.0).sqrt()).collect();
    let largest = norms.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
    if !(largest > 0.0) || !s2.is_finite() {
        return (sigma, correlations);
    }
    let live: Vec<usize> = (0..cols).filter(|&c| norms[c].is_finite() && norms[c] > 1e-9 * largest).collect();
    if live.is_empty() {
        return (sigma, correlations);
    }
    // equilibrated normal matrix over the live columns: unit diagonal
    let m = live.len();
    let mut a = DMatrix::zeros(m, m);
    for (p, &cp) in live.iter().enumerate() {
        for (q, &cq) in live.iter().enumerate().skip(p) {
            let v = jtj[(cp, cq)] / (norms[cp] * norms[cq]);
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
    fn distinct_best_skips_points_close_to_a_better_one() {
        let pts = vec![
            (3.0, vec![0.9, 0.9]),
            (1.0, vec![0.5, 0.5]),
            (1.5, vec![0.52, 0.5]), // within 0.05 (rms) of the best: skipped
            (2.0, vec![0.1, 0.2]),
            (f64::NAN, vec![0.0, 0.0]),
        ];
        let best = distinct_best(&pts, 3);
        assert_eq!(best.iter().map(|p| p.0).collect::<Vec<_>>(), vec![1.0, 2.0, 3.0]);
        assert_eq!(distinct_best(&pts, 1)[0].1, vec![0.5, 0.5]);
    }

    #[test]
    fn normal_equations_from_sparse_columns_match_the_dense_product() {
        let m = 40;
        let dense = |k: usize| (0..m).map(|i| ((i * (k + 3)) as f64 * 0.17).sin()).collect::<Vec<f64>>();
        let cols = vec![
            Column { offset: 0, values: dense(0) },
            Column { offset: 0, values: dense(1) },
            Column { offset: 5, values: dense(2)[5..20].to_vec() },
            Column { offset: 20, values: dense(3)[20..40].to_vec() },
        ];
        let r: Vec<f64> = (0..m).map(|i| (i as f64 * 0.3).cos()).collect();
        let j = DMatrix::from_fn(m, cols.len(), |i, c| {
            let col = &cols[c];
            if i >= col.offset && i < col.offset + col.values.len() {
                col.values[i - col.offset]
            } else {
                0.0
            }
        });
        let (a, g) = normal_equations(&cols, &r);
        let (a2, g2) = (j.transpose() * &j, j.transpose() * DVector::from_vec(r.clone()));
        assert!((a - a2).amax() < 1e-12 && (g - g2).amax() < 1e-12);
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
