//! A fit with an evaluation budget ends at the same point whatever the machine's speed or
//! thread count: the same small fit with 1 and 2 rayon threads gives bit-identical values.

use petzval_fit::fit::{FitOptions, Problem};
use petzval_fit::synth::{write_captures, Shot, SynthOptions};
use petzval_fit::{solve, Manifest, Model};

#[test]
fn a_budgeted_fit_is_bit_identical_with_one_and_two_threads() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-determinism-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lens = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model::new(lens.prescription().clone());
    truth.camera.sensor_offset_mm = 0.03;
    let r3: petzval_fit::Param = "surface.3.radius_mm".parse().unwrap();
    let r = truth.get(&r3).unwrap();
    truth.set(&r3, r * 1.01).unwrap();
    let shots = [
        Shot { source_m: [0.0, 0.0, 2.0], focus_m: 2.0, f_number: 2.8 },
        Shot { source_m: [0.15, 0.1, 1.7], focus_m: 2.0, f_number: 2.8 },
    ];
    let free = format!(
        "[[free]]\nparam = \"sensor.offset_mm\"\nmin = -0.2\nmax = 0.2\n\n\
         [[free]]\nparam = \"surface.3.radius_mm\"\nmin = {}\nmax = {}\n\n",
        r * 0.97,
        r * 1.03
    );
    let manifest =
        write_captures(&dir, "double-gauss-50mm", &truth, &shots, &free, 32, &SynthOptions::default()).unwrap();
    let manifest = Manifest::load(&manifest).unwrap();
    // a time limit far beyond what the budget takes: the budget alone ends every stage
    // the grid pattern (the default) and the spiral
    for subsamples in [2, 0] {
        check(&manifest, subsamples);
    }
    std::fs::remove_dir_all(&dir).ok();
}

fn check(manifest: &Manifest, subsamples: usize) {
    let options = FitOptions {
        time_limit_s: 600.0,
        rays: 4096,
        subsamples,
        max_evaluations: 120,
        starts: 2,
        ..Default::default()
    };
    let problem = Problem::new(manifest, &options).unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| solve::run(&problem, &options))
    };
    let (one, two) = (run(1), run(2));
    let bits = |r: &solve::FitResult| {
        let mut v: Vec<u64> = r.params.iter().map(|p| p.value.to_bits()).collect();
        v.extend(r.params.iter().map(|p| p.sigma.unwrap_or(f64::NAN).to_bits()));
        v.extend(r.shifts_px.iter().flat_map(|s| [s.x.to_bits(), s.y.to_bits()]));
        v.extend(r.residuals.iter().map(|x| x.to_bits()));
        v
    };
    println!(
        "subsamples {subsamples}: 1 thread: {:?} {:?} {:.1} s; 2 threads: {:.1} s; evaluations {:?}",
        one.params.iter().map(|p| p.value).collect::<Vec<_>>(),
        one.residuals,
        one.seconds,
        two.seconds,
        one.evaluations
    );
    assert_eq!(one.evaluations, two.evaluations);
    assert_eq!(bits(&one), bits(&two), "1 thread {:?}\n2 threads {:?}", one.params, two.params);
    // the budget bounds the stages' evaluations (the uncertainty's Jacobian is outside it)
    let total: usize = one.evaluations.iter().filter(|(k, _)| k != "uncertainty").map(|(_, v)| v).sum();
    assert!(total <= options.max_evaluations, "{total} evaluations over the budget");
    assert!(total >= options.max_evaluations * 3 / 4, "only {total} of the budget's evaluations used");
    // and the fit did its job (the spiral's run; with the grid this 32² two-capture fit ends in
    // the focus valley's side branch at this budget: residuals 26 % and 21 %, see docs/lens-fit.md)
    if subsamples == 0 {
        let offset = one.params.iter().find(|p| p.name == "sensor.offset_mm").unwrap().value;
        assert!((offset - 0.03).abs() < 0.01, "offset {offset}");
    }
}
