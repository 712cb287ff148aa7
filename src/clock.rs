//! A stopwatch that builds everywhere: `std::time::Instant` natively, and no clock on
//! wasm32-unknown-unknown, whose `std` has none (`Instant::now` panics there), where
//! every reading is 0.

/// Seconds since it started or last restarted (0 on wasm32).
pub(crate) struct Stopwatch {
    #[cfg(not(target_arch = "wasm32"))]
    t: std::time::Instant,
}

impl Stopwatch {
    pub(crate) fn start() -> Stopwatch {
        Stopwatch {
            #[cfg(not(target_arch = "wasm32"))]
            t: std::time::Instant::now(),
        }
    }

    /// Seconds since the start or the last [`Stopwatch::split`].
    pub(crate) fn seconds(&self) -> f64 {
        #[cfg(not(target_arch = "wasm32"))]
        {
            self.t.elapsed().as_secs_f64()
        }
        #[cfg(target_arch = "wasm32")]
        0.0
    }

    /// [`Stopwatch::seconds`], restarting the count.
    pub(crate) fn split(&mut self) -> f64 {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let now = std::time::Instant::now();
            let t = (now - self.t).as_secs_f64();
            self.t = now;
            t
        }
        #[cfg(target_arch = "wasm32")]
        0.0
    }
}
