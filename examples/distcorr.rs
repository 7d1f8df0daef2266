//! Prints fme's distance correlation of the two columns of a CSV file (no header), at full
//! precision: `cargo run --example distcorr -- FILE.csv`. Used by `scripts/check_distcorr.py` to
//! compare with PyPI `dcor`.

use std::process::ExitCode;

fn main() -> ExitCode {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: distcorr FILE.csv  (two numeric columns, no header)");
        return ExitCode::from(2);
    };
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {path}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let mut parts = line.split(',').map(|s| s.trim().parse::<f64>());
        match (parts.next(), parts.next(), parts.next()) {
            (Some(Ok(a)), Some(Ok(b)), None) => {
                x.push(a);
                y.push(b);
            }
            _ => {
                eprintln!("error: {path}:{}: expected two numbers", i + 1);
                return ExitCode::FAILURE;
            }
        }
    }
    match fme::eval::distance_correlation(&x, &y) {
        Some(d) => {
            println!("{d:.17e}");
            ExitCode::SUCCESS
        }
        None => {
            eprintln!("error: {path}: need at least two finite pairs");
            ExitCode::FAILURE
        }
    }
}
