//! Chooses the fit's stages from what is free.
//!
//! In LRTF correction mode (a `correction.*` coefficient is free and no prescription parameter
//! is) the start, the uncorrected table, is next to the solution and the residuals are close to
//! linear in the coefficients, so Levenberg–Marquardt runs alone from it: a global CRS2 search
//! over the coefficients' box mostly samples wild corrections. Measured on nine synthetic
//! captures (double-gauss-50mm with surface 3's radius +0.5 % and the sensor 0.05 mm back,
//! eight correction terms, 30 s): CRS2 + BOBYQA + LM ended at 15–37 % residuals, LM alone at
//! 1.8–2.3 % in focus and 6.9–7.8 % on the two defocused captures (time-limited, before the
//! evaluation budgets). Every other fit runs the stages of
//! [`solve::run`] as its options say.

use crate::fit::{FitOptions, Problem};
use crate::solve::{self, FitResult};

/// Whether a fit is in LRTF correction mode: a correction coefficient is free and no lens
/// parameter is (camera parameters may be).
pub fn is_correction_mode(problem: &Problem) -> bool {
    problem.free.iter().any(|f| f.param.is_correction()) && !problem.free.iter().any(|f| f.param.is_lens())
}

/// Runs the fit with the stages its free parameters call for.
pub fn run(problem: &Problem, options: &FitOptions) -> FitResult {
    run_with_progress(problem, options, &|_| {})
}

/// [`run`] reporting progress.
pub fn run_with_progress(problem: &Problem, options: &FitOptions, progress: solve::ProgressFn) -> FitResult {
    if is_correction_mode(problem) {
        let lm_only = FitOptions { global_share: 0.0, local_share: 0.0, ..*options };
        return solve::run_with_progress(problem, &lm_only, progress);
    }
    solve::run_with_progress(problem, options, progress)
}
