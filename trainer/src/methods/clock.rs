//! The clock every method is timed with: the CPU time of the calling thread where the
//! platform has one (unix), so that other work on the machine does not count in a method's
//! cost, wall-clock time elsewhere. `mochi compare` steps every method on one thread (a
//! one-thread pool, so that the simulator's parallel sums run on the same thread) and reads
//! this clock around each step.

/// A point in time on the clock.
#[derive(Clone, Copy, Debug)]
pub struct Stopwatch {
    #[cfg(unix)]
    start: f64,
    #[cfg(not(unix))]
    start: std::time::Instant,
}

impl Stopwatch {
    /// Starts timing now.
    pub fn start() -> Self {
        Stopwatch {
            #[cfg(unix)]
            start: thread_seconds(),
            #[cfg(not(unix))]
            start: std::time::Instant::now(),
        }
    }

    /// Seconds since [`Stopwatch::start`].
    pub fn seconds(&self) -> f64 {
        #[cfg(unix)]
        return thread_seconds() - self.start;
        #[cfg(not(unix))]
        return self.start.elapsed().as_secs_f64();
    }
}

#[cfg(unix)]
fn thread_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Busy work shows up on the clock; sleeping does not (on unix, where it is CPU time).
    #[test]
    fn the_clock_counts_work() {
        let watch = Stopwatch::start();
        let mut x = 1.0f64;
        for i in 0..2_000_000 {
            x = (x + i as f64).sqrt();
        }
        assert!(x > 0.0);
        let busy = watch.seconds();
        assert!(busy > 0.0);
        #[cfg(unix)]
        {
            let watch = Stopwatch::start();
            std::thread::sleep(std::time::Duration::from_millis(50));
            assert!(watch.seconds() < 0.025, "{}", watch.seconds());
        }
    }
}
