//! Long computations run in chunks of receivers, with progress reports and cancellation
//! between chunks, on the caller's thread (so a Python callback can run there).

use rayon::prelude::*;

use crate::error::{Error, Result};

/// Called on the caller's thread with the fraction of receivers done; returning false cancels.
pub type Progress<'a> = &'a mut dyn FnMut(f32) -> bool;

/// Receivers per chunk: about 1/64 of the work, so progress moves smoothly, but never fewer
/// than keep every core busy between reports.
fn chunk_rows(rows: usize) -> usize {
    (rows / 64).max(1024)
}

/// Runs `work(row, scratch, out_row)` for every row of `out` (`k` values each) on all cores,
/// one chunk at a time, and reports progress after each chunk. `Err(Cancelled)` as soon as
/// `progress` returns false; rows not reached are left as they were.
pub fn par_rows<S>(
    out: &mut [f32],
    k: usize,
    progress: Progress,
    init: impl Fn() -> S + Sync + Send,
    work: impl Fn(usize, &mut S, &mut [f32]) + Sync + Send,
) -> Result<()> {
    par_rows_with::<S, ()>(out, k, &mut [], progress, init, |row, scratch, values, _| work(row, scratch, values))
}

/// `par_rows` with one more item per row, `extra[row]`, given to `work` as well; an empty
/// `extra` gives None to every row.
pub fn par_rows_with<S, T: Send>(
    out: &mut [f32],
    k: usize,
    extra: &mut [T],
    progress: Progress,
    init: impl Fn() -> S + Sync + Send,
    work: impl Fn(usize, &mut S, &mut [f32], Option<&mut T>) + Sync + Send,
) -> Result<()> {
    let k = k.max(1);
    let rows = out.len() / k;
    assert!(extra.is_empty() || extra.len() == rows, "par_rows_with: {} extra items for {rows} rows", extra.len());
    let chunk = chunk_rows(rows);
    let mut done = 0;
    let mut extra_blocks = extra.chunks_mut(chunk);
    for block in out.chunks_mut(chunk * k) {
        let first = done;
        let rows_here = block.chunks_mut(k).len();
        match extra_blocks.next() {
            Some(items) => block.par_chunks_mut(k).zip(items.par_iter_mut()).enumerate().for_each_init(&init, |scratch, (i, (row, item))| {
                work(first + i, scratch, row, Some(item))
            }),
            None => block.par_chunks_mut(k).enumerate().for_each_init(&init, |scratch, (i, row)| work(first + i, scratch, row, None)),
        }
        done += rows_here;
        if !progress(done as f32 / rows as f32) {
            return Err(Error::Cancelled);
        }
    }
    Ok(())
}

/// `work(row, scratch)` for rows 0..rows on all cores, collected in order, one chunk at a time
/// with progress as `par_rows` (for results of varying size).
pub fn par_collect<S, T: Send>(
    rows: usize,
    progress: Progress,
    init: impl Fn() -> S + Sync + Send,
    work: impl Fn(usize, &mut S) -> T + Sync + Send,
) -> Result<Vec<T>> {
    let chunk = chunk_rows(rows);
    let mut out = Vec::with_capacity(rows);
    for first in (0..rows).step_by(chunk) {
        let end = (first + chunk).min(rows);
        out.par_extend((first..end).into_par_iter().map_init(&init, |scratch, r| work(r, scratch)));
        if !progress(end as f32 / rows as f32) {
            return Err(Error::Cancelled);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_is_computed_once_and_progress_ends_at_one() {
        let mut out = vec![0.0f32; 5000 * 2];
        let mut reports = Vec::new();
        par_rows(&mut out, 2, &mut |f| {
            reports.push(f);
            true
        }, || (), |r, _, row| row.fill(r as f32))
        .unwrap();
        assert!(out.chunks(2).enumerate().all(|(r, row)| row == [r as f32, r as f32]));
        assert_eq!(*reports.last().unwrap(), 1.0);
        assert!(reports.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn extra_items_pair_with_their_rows() {
        let mut out = vec![0.0f32; 5000 * 3];
        let mut extra: Vec<usize> = (0..5000).map(|r| r * 7).collect();
        par_rows_with(&mut out, 3, &mut extra, &mut |_| true, || (), |r, _, row, item| {
            let item = item.unwrap();
            row.fill(*item as f32);
            *item = r;
        })
        .unwrap();
        assert!(out.chunks(3).enumerate().all(|(r, row)| row == [(r * 7) as f32; 3]));
        assert!(extra.iter().enumerate().all(|(r, &x)| x == r));
        let mut none = vec![0.0f32; 10];
        par_rows_with::<(), u8>(&mut none, 1, &mut [], &mut |_| true, || (), |_, _, row, item| {
            assert!(item.is_none());
            row[0] = 1.0;
        })
        .unwrap();
        assert!(none.iter().all(|&x| x == 1.0));
    }

    #[test]
    fn collected_rows_come_in_order_and_cancel_stops() {
        let rows = par_collect(5000, &mut |_| true, || (), |r, _| vec![r; r % 3]).unwrap();
        assert!(rows.iter().enumerate().all(|(r, v)| v.len() == r % 3 && v.iter().all(|&x| x == r)));
        let mut calls = 0;
        let cancelled = par_collect(5000, &mut |_| {
            calls += 1;
            false
        }, || (), |r, _| r);
        assert!(matches!(cancelled, Err(Error::Cancelled)));
        assert_eq!(calls, 1);
    }

    #[test]
    fn cancelling_stops_after_the_current_chunk() {
        let mut out = vec![-1.0f32; 100_000];
        let result = par_rows(&mut out, 1, &mut |_| false, || (), |_, _, row| row[0] = 1.0);
        assert_eq!(result, Err(Error::Cancelled));
        assert!(out.iter().any(|&v| v == -1.0));
    }
}
