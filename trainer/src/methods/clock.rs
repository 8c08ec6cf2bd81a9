//! The clock every method is timed with: the CPU time of the process where the platform has
//! one (unix): the work a step took on all of the process's threads (the simulator's sums
//! may run on several), and not the other work on the machine. Wall-clock time elsewhere.
//! `mochi compare` steps every method on a one-thread pool, so the figure is also the time
//! one core takes.

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
            start: process_seconds(),
            #[cfg(not(unix))]
            start: std::time::Instant::now(),
        }
    }

    /// Seconds since [`Stopwatch::start`].
    pub fn seconds(&self) -> f64 {
        #[cfg(unix)]
        return process_seconds() - self.start;
        #[cfg(not(unix))]
        return self.start.elapsed().as_secs_f64();
    }
}

#[cfg(unix)]
fn process_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Busy work shows up on the clock, and the clock never runs backwards. (Other tests
    /// run on other threads of the same process, so what a sleep costs is not checked here.)
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
        assert!(watch.seconds() >= busy);
    }
}
