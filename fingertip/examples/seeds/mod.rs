//! The `[RUNS] [BASE_SEED]` arguments the analysis examples share.

/// Runs per scenario and the first seed, from the command line: `RUNS` (default
/// `default_runs`) at least 1, and the seeds `BASE_SEED..BASE_SEED + RUNS` (default base 1)
/// within `u64`.
pub fn runs_and_base(default_runs: u64) -> Result<(u64, u64), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: u64 = args
        .next()
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(default_runs);
    let base: u64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(1);
    if runs == 0 || base.checked_add(runs).is_none() {
        return Err(
            format!("RUNS = {runs} must be at least 1, and BASE_SEED + RUNS within u64").into(),
        );
    }
    Ok((runs, base))
}
