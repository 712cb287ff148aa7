//! The one place that knows whether rayon is there. With the `parallel` feature
//! these run on rayon's pool (`RAYON_NUM_THREADS` sets its size); without it they
//! are plain loops. Results never depend on the thread count: work is split into
//! fixed index ranges and written to fixed places.

#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// `(0..n).map(f).collect()`, in parallel when enabled. Order is preserved.
pub fn map<T: Send, F: Fn(usize) -> T + Sync + Send>(n: usize, f: F) -> Vec<T> {
    #[cfg(feature = "parallel")]
    {
        (0..n).into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        (0..n).map(f).collect()
    }
}

/// Calls `f(chunk_index, chunk)` on consecutive chunks of `chunk_len` elements
/// (the last may be shorter), in parallel when enabled.
pub fn for_each_chunk_mut<T: Send, F: Fn(usize, &mut [T]) + Sync + Send>(
    data: &mut [T],
    chunk_len: usize,
    f: F,
) {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    {
        data.par_chunks_mut(chunk_len).enumerate().for_each(|(i, c)| f(i, c));
    }
    #[cfg(not(feature = "parallel"))]
    {
        data.chunks_mut(chunk_len).enumerate().for_each(|(i, c)| f(i, c));
    }
}

/// Calls `f(chunk_index, chunk)` on consecutive chunks of `chunk_len` elements and
/// returns the results in chunk order (parallel when enabled). For per-chunk partial
/// results (e.g. sums) that are then combined in a fixed order.
pub fn map_chunks_mut<T: Send, R: Send, F: Fn(usize, &mut [T]) -> R + Sync + Send>(
    data: &mut [T],
    chunk_len: usize,
    f: F,
) -> Vec<R> {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    {
        data.par_chunks_mut(chunk_len).enumerate().map(|(i, c)| f(i, c)).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        data.chunks_mut(chunk_len).enumerate().map(|(i, c)| f(i, c)).collect()
    }
}

/// Runs two closures, concurrently when enabled.
pub fn join<A: Send, B: Send>(a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

/// Number of worker threads that `map` and friends use.
pub fn num_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

/// Sizes the global pool to `n` worker threads (the CLI's `--threads`), as
/// `RAYON_NUM_THREADS` would; call it before any parallel work. Returns the number of
/// threads that will run: `n`, or 1 in a build without the `parallel` feature.
///
/// # Errors
/// `Usage` for `n` = 0, or when the pool was already built (by earlier parallel work
/// or an earlier call).
pub fn set_threads(n: usize) -> crate::Result<usize> {
    if n == 0 {
        return Err(crate::Error::Usage("the thread count must be at least 1".into()));
    }
    #[cfg(feature = "parallel")]
    {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| crate::Error::Usage(format!("cannot set the thread count to {n}: {e}")))?;
        Ok(n)
    }
    #[cfg(not(feature = "parallel"))]
    {
        Ok(1)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn map_preserves_order_and_chunks_cover_everything() {
        let v = super::map(1000, |i| i * 2);
        assert!(v.iter().enumerate().all(|(i, &x)| x == 2 * i));
        let mut d = vec![0usize; 1003];
        super::for_each_chunk_mut(&mut d, 10, |ci, c| {
            for (j, x) in c.iter_mut().enumerate() {
                *x = ci * 10 + j;
            }
        });
        assert!(d.iter().enumerate().all(|(i, &x)| x == i));
    }

    #[test]
    fn zero_threads_is_refused() {
        let e = super::set_threads(0).unwrap_err().to_string();
        assert!(e.contains("at least 1"), "{e}");
    }
}
