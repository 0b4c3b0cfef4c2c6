//! Times `Solver::solve` on a mesh dumped by bench/dump_mesh.py (u32 frames, vertices,
//! triangles; f32 frames x vertices x 3; u32 triangles x 3), for profiling without Python:
//!
//!     cargo run --release --example profile_solver -- mesh.bin [downsample] [table] [near_scale] [coarse triangles] [far_lod]
//!
//! A `-` leaves one argument at its default (`- - 2.5 - 0.9`).
//!
//! With `--features hemishadow-engine/census`, also prints what the rasterized triangles added to their masks
//! (`rasterizer::census`; every mask is then drawn twice, so the times mean nothing).
//!
//! `PROFILE_SOLVES=N` times exactly N solves (for instruction counts under valgrind, which
//! are steady where times on a shared machine are not); by default, up to 100 in 5 s.
//!
//! `PROFILE_AGAINST="downsample table near_scale coarse far_lod"` (the same optional arguments) builds
//! a second solver and alternates the two solve by solve, printing both: on a shared machine
//! whose speed drifts by tens of percent within minutes, only such pairs compare settings.

use std::time::Instant;

use hemishadow_engine::{Blockers, Settings, Solver};

fn read_mesh(path: &str) -> (Vec<Vec<[f32; 3]>>, Vec<[u32; 3]>) {
    let bytes = std::fs::read(path).expect("mesh file");
    let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let (frames, vertices, triangles) = (word(0) as usize, word(1) as usize, word(2) as usize);
    let float = |i: usize| f32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let positions = (0..frames)
        .map(|f| (0..vertices).map(|v| [0, 1, 2].map(|a| float(3 + (f * vertices + v) * 3 + a))).collect())
        .collect();
    let base = 3 + frames * vertices * 3;
    let tris = (0..triangles).map(|t| [0, 1, 2].map(|a| word(base + 3 * t + a))).collect();
    (positions, tris)
}

/// CPU time of this process (all threads), in ms: robust to other load on a shared machine.
fn cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) * 10.0 // utime, stime in 1/100 s
}

/// A warm solver (one solve done) with the optional arguments `[downsample] [table]
/// [near_scale] [coarse triangles] [far_lod]`, reuse off.
fn warm_solver(frames: &[Vec<[f32; 3]>], triangles: &[[u32; 3]], args: &[String]) -> Solver {
    let arg = |i: usize| args.get(i).filter(|s| *s != "-").map(|s| s.parse::<f32>().unwrap());
    let settings = Settings {
        downsample: arg(0).map(|d| d as usize),
        table_resolution: arg(1).map_or(Settings::default().table_resolution, |t| t as usize),
        ..Settings::default()
    };
    let near_scale = arg(2).unwrap_or(Blockers::default().near_scale);
    let far_lod = arg(4).unwrap_or(Blockers::default().far_lod);
    let coarse_triangles = arg(3).map(|c| c as usize);
    let blockers = Blockers { reuse: false, coarse_triangles, near_scale, far_lod, ..Blockers::default() };
    let mut solver = Solver::new(&frames[0], triangles, &settings, blockers).unwrap();
    solver.solve(&frames[1], None, None).unwrap();
    solver
}

/// Solves `solvers` in turn, `rounds` times, and prints each one's times.
fn alternate(frames: &[Vec<[f32; 3]>], solvers: &mut [(String, Solver)], rounds: usize) {
    let mut times = vec![Vec::new(); solvers.len()];
    for round in 0..rounds {
        let frame = &frames[1 + round % (frames.len() - 1)];
        for ((_, solver), times) in solvers.iter_mut().zip(&mut times) {
            let t = Instant::now();
            solver.solve(frame, None, None).unwrap();
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    for ((name, solver), mut t) in solvers.iter().zip(times) {
        t.sort_by(f64::total_cmp);
        let blockers = solver.stats().blockers_per_receiver;
        println!("[{name}]: fastest {:.2} ms, tenth percentile {:.2}, median {:.2} over {rounds} solves, {blockers:.0} blockers per receiver", t[0], t[t.len() / 10], t[t.len() / 2]);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (frames, triangles) = read_mesh(&args[1]);
    let mut solver = warm_solver(&frames, &triangles, &args[2..]);
    let solves = std::env::var("PROFILE_SOLVES").ok().and_then(|n| n.parse::<usize>().ok());
    if let Ok(against) = std::env::var("PROFILE_AGAINST") {
        let other: Vec<String> = against.split_whitespace().map(String::from).collect();
        let other = warm_solver(&frames, &triangles, &other);
        let name = if args.len() > 2 { args[2..].join(" ") } else { "default".into() };
        alternate(&frames, &mut [(name, solver), (against, other)], solves.unwrap_or(40));
        return;
    }
    let mut times = Vec::new();
    let start = Instant::now();
    let cpu_start = cpu_ms();
    while match solves {
        Some(n) => times.len() < n,
        None => times.len() < 5 || (start.elapsed().as_secs_f32() < 5.0 && times.len() < 100),
    } {
        let frame = &frames[1 + times.len() % (frames.len() - 1)];
        let t = Instant::now();
        solver.solve(frame, None, None).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let cpu_per_solve = (cpu_ms() - cpu_start) / times.len() as f64;
    #[cfg(feature = "census")]
    print_census();
    times.sort_by(f64::total_cmp);
    let stats = solver.stats();
    println!(
        "{}: {} vertices, {:.2} ms median over {} solves (fastest {:.2} ms; {:.1} CPU ms per solve), {:.0} blockers per receiver",
        args[1], frames[0].len(), times[times.len() / 2], times.len(), times[0], cpu_per_solve, stats.blockers_per_receiver
    );
}

/// The census as shares of every triangle rasterized, by outcome and height.
#[cfg(feature = "census")]
fn print_census() {
    let counts = hemishadow_engine::rasterizer::census::counts();
    let total: u64 = counts.iter().flatten().sum();
    let sources = hemishadow_engine::rasterizer::census::packets();
    let all: u64 = sources.iter().map(|s| s[0]).sum();
    for (name, [packets, offered, drawn, none]) in hemishadow_engine::rasterizer::census::SOURCES.iter().zip(sources) {
        let per_packet = |n: u64| n as f64 / packets.max(1) as f64;
        println!(
            "{name:>8}: {packets} packets ({:.1} % of all): {:.1} lanes each, {:.1} drawn, {:.1} % with none drawn",
            100.0 * packets as f64 / all.max(1) as f64,
            per_packet(offered),
            per_packet(drawn),
            100.0 * per_packet(none)
        );
    }
    let share = |n: u64| 100.0 * n as f64 / total.max(1) as f64;
    println!("census of {total} triangles (highest corner's z: below 0.1 / below 0.5 / above; % of all)");
    for (name, row) in ["covers no cell", "covers only blocked cells", "blocks new cells"].iter().zip(counts) {
        let parts: Vec<String> = row.iter().map(|&n| format!("{:.1}", share(n))).collect();
        println!("  {name:>26}: {:.1} % ({})", share(row.iter().sum()), parts.join(" / "));
    }
}
