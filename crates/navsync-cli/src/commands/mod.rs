pub mod array;
pub mod bench;
pub mod convert;
pub mod eval;
pub mod fuse;
pub mod imu;
pub mod live;
pub mod simulate;
pub mod speed_sim;
pub mod sync;
pub mod track;

/// Parses "a,b,c" into three numbers.
pub fn parse_triplet(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .map_err(|_| format!("'{x}' is not a number"))
        })
        .collect::<Result<_, _>>()?;
    v.try_into()
        .map_err(|_| format!("'{s}': expected three comma-separated numbers"))
}

/// Prints at most `limit` diagnostics and a count of the rest.
pub fn print_diagnostics(d: &navsync::Diagnostics, limit: usize) {
    for item in d.items.iter().take(limit) {
        eprintln!("  {item}");
    }
    if d.total > limit {
        eprintln!("  … and {} more (all in summary.json)", d.total - limit);
    }
}
