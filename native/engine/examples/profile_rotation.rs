//! Time of ShRotator::to_world (5 bands) on 200,000 random frames, and a checksum of the
//! outputs' bits (equal checksums: the same results). Run under cachegrind for instruction
//! counts: `cargo run --release -p hemishadow-engine --example profile_rotation`.
use hemishadow_engine::sh::ShBasis;
use hemishadow_engine::sh_rotation::ShRotator;
fn main() {
    let basis = ShBasis::new(5).unwrap();
    let rot = ShRotator::new(basis);
    let n = 200_000;
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 33) as f32 / (1u64 << 31) as f32 * 2.0 - 1.0
    };
    let mut axes_list = Vec::new();
    let mut locals = Vec::new();
    for _ in 0..n {
        let v = [rnd(), rnd(), rnd() + 0.01];
        let n = hemishadow_engine::mesh::normalize(v).unwrap();
        let (t, b) = hemishadow_engine::mesh::tangent_frame(n);
        axes_list.push([t, b, n]);
        locals.push((0..25).map(|_| rnd()).collect::<Vec<f32>>());
    }
    let mut out = [0.0f32; 25];
    let mut sum = 0u64;
    let t0 = std::time::Instant::now();
    for (a, l) in axes_list.iter().zip(&locals) {
        rot.to_world(*a, l, &mut out);
        sum = sum.wrapping_add(out.iter().map(|v| v.to_bits() as u64).sum::<u64>());
    }
    let dt = t0.elapsed();
    println!("{:.1} ns per to_world, checksum {sum}", dt.as_nanos() as f64 / n as f64);
}
