//! Our triangulation beside delaunator (the sweep Polylidar3D's C++ uses, with its inexact
//! in-circle test) and spade (exact, incremental) on the same seeded clouds of 1.5 k to 1 M points.
//!
//! `cargo bench -p landing-geometry --bench triangulation -- --measurement-time 5 --warm-up-time 2`
//! (add a filter such as `1.5k/` or `/ours/` to narrow it). Each triangulator takes the points in
//! its own input layout, made outside the timed loop: ours `[f64; 3]` (z ignored), delaunator its
//! `Point`, spade its vertices (built inside, as `triangulate_spade` must). spade is left out at
//! 1 M (about a second a run).
//!
//! Every size is measured twice: `triangulation/…` by the wall clock, as criterion does, and
//! `triangulation-cpu/…` by this thread's CPU time (Linux `CLOCK_THREAD_CPUTIME_ID`). On a shared,
//! loaded machine the wall clock also counts the slices other processes held the core, which
//! swamps differences of a few per cent; CPU time does not (cache and core sharing still show).

use std::hint::black_box;
use std::time::Duration;

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use landing_geometry::triangulation::{EMPTY, Triangulation, triangulate};

#[path = "../tests/support/spade.rs"]
mod spade;

#[path = "../tests/support/clouds.rs"]
mod clouds;

fn benches<M: Measurement>(c: &mut Criterion<M>, clock: &str) {
    for (n, label) in clouds::SIZES {
        let (_, pts) = clouds::cloud(n);
        let dpts = clouds::delaunator_points(&pts);
        let mut g = c.benchmark_group(format!("{clock}/{label}"));
        if n >= 100_000 {
            g.sample_size(10);
        }
        g.bench_function(BenchmarkId::new("ours", label), |b| {
            b.iter(|| triangulate(black_box(&pts)).unwrap())
        });
        g.bench_function(BenchmarkId::new("delaunator", label), |b| {
            b.iter(|| delaunator::triangulate(black_box(&dpts)))
        });
        if n <= 100_000 {
            g.bench_function(BenchmarkId::new("spade", label), |b| {
                b.iter(|| spade::triangulate_spade(black_box(&pts)))
            });
        }
        g.finish();
    }
}

fn wall(c: &mut Criterion) {
    benches(c, "triangulation");
}

fn cpu(c: &mut Criterion<ThreadCpuTime>) {
    benches(c, "triangulation-cpu");
}

/// This thread's CPU time, as criterion's measurement (shown like wall time).
struct ThreadCpuTime(WallTime);

impl Measurement for ThreadCpuTime {
    type Intermediate = Duration;
    type Value = Duration;

    fn start(&self) -> Duration {
        thread_cpu_time()
    }
    fn end(&self, start: Duration) -> Duration {
        thread_cpu_time().saturating_sub(start)
    }
    fn add(&self, a: &Duration, b: &Duration) -> Duration {
        *a + *b
    }
    fn zero(&self) -> Duration {
        Duration::ZERO
    }
    fn to_f64(&self, value: &Duration) -> f64 {
        value.as_nanos() as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        self.0.formatter()
    }
}

#[repr(C)]
struct Timespec {
    tv_sec: i64,
    tv_nsec: i64,
}

unsafe extern "C" {
    /// POSIX `clock_gettime` from the C library std already links (64-bit Linux layout).
    fn clock_gettime(clock: i32, time: *mut Timespec) -> i32;
}

/// Linux's `CLOCK_THREAD_CPUTIME_ID`.
const CLOCK_THREAD_CPUTIME_ID: i32 = 3;

/// CPU time this thread has used, to the nanosecond (not at scheduler ticks, as
/// `/proc/thread-self/schedstat` advances for a running thread).
fn thread_cpu_time() -> Duration {
    let mut t = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a live, writable timespec with the C layout on 64-bit Linux; clock_gettime
    // writes only it and keeps no pointer.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    Duration::new(t.tv_sec as u64, t.tv_nsec as u32)
}

criterion_group! {
    name = by_wall_clock;
    config = Criterion::default().warm_up_time(Duration::from_secs(2));
    targets = wall
}
criterion_group! {
    name = by_cpu_time;
    config = Criterion::default()
        .warm_up_time(Duration::from_secs(2))
        .with_measurement(ThreadCpuTime(WallTime));
    targets = cpu
}
criterion_main!(by_wall_clock, by_cpu_time);
