//! Writes a generated site file to stdout (DESIGN §17): the large pit used
//! for scale, reproducible by its seed.
//!
//! `cargo run -p control --example site_gen -- large-pit 40 520 > sim/sites/large-pit.json`

use control::site::generate::large_pit;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: site_gen large-pit SEED FEATURES";
    match args.as_slice() {
        [kind, seed, n] if kind == "large-pit" => {
            let seed: u64 = seed
                .parse()
                .map_err(|_| format!("seed {seed:?}: {usage}"))?;
            let n: usize = n.parse().map_err(|_| format!("features {n:?}: {usage}"))?;
            print!("{}", large_pit(seed, n).to_json());
            Ok(())
        }
        _ => Err(usage.to_string()),
    }
}
