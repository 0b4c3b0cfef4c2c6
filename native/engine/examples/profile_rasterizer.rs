//! Nanoseconds per triangle of the batch rasterizer on random triangles, per table resolution:
//!
//!     cargo run --release --example profile_rasterizer

use std::time::Instant;

use hemishadow_engine::disk_mask::Mask;
use hemishadow_engine::plane_table::PlaneTable;
use hemishadow_engine::rasterizer::{triangle_mask, TriangleBatch};

fn main() {
    let mut state = 12345u64;
    let mut random = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    let triangles: Vec<[[f32; 3]; 3]> = (0..1 << 16)
        .map(|_| {
            let centre = [random() * 4.0, random() * 4.0, random().abs() * 2.0 + 0.1];
            [0, 1, 2].map(|_| [0, 1, 2].map(|a| centre[a] + 0.2 * random()))
        })
        .collect();
    for resolution in [32, 48, 64, 96, 128] {
        let table = PlaneTable::shared(resolution).unwrap();
        let mut checksum = 0u32;
        let start = Instant::now();
        let rounds = 40;
        for _ in 0..rounds {
            for receiver in triangles.chunks(256) {
                let mut mask = Mask::EMPTY;
                let mut batch = TriangleBatch::default();
                for [a, b, c] in receiver {
                    batch.push(&table, *a, *b, *c, &mut mask);
                }
                batch.finish(&table, &mut mask);
                checksum = checksum.wrapping_add(mask.count());
            }
        }
        let ns = start.elapsed().as_secs_f64() * 1e9 / (rounds * triangles.len()) as f64;
        let start = Instant::now();
        for _ in 0..rounds {
            for receiver in triangles.chunks(256) {
                let mut mask = Mask::EMPTY;
                for [a, b, c] in receiver {
                    if let Some(m) = triangle_mask(&table, *a, *b, *c) {
                        mask.or_assign(&m);
                    }
                }
                checksum = checksum.wrapping_add(mask.count());
            }
        }
        let scalar = start.elapsed().as_secs_f64() * 1e9 / (rounds * triangles.len()) as f64;
        println!("table {resolution:>3}: batch {ns:.1}, one by one {scalar:.1} ns per triangle (checksum {checksum})");
    }
}
