//! Plain progress lines on stderr for a bake or a validation whose stderr is not a terminal
//! (the log of a batch job, `nohup`, CI), where the progress bars draw nothing: cells done
//! and the sampler's points and face rectangles so far ([`PlainProgress`]), or rays cast
//! ([`plain_rays`]), with the time elapsed and an estimate of what is left, at most one line
//! per interval (`--progress-every`).

use std::sync::Mutex;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use umbrasweep::bake::{RectPace, SamplerProgress};

/// `--progress-every` (`bake`, `validate`): seconds between two plain progress lines, or none.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProgressEvery(pub Option<f64>);

/// `--progress-every`, shared by `bake` and `validate`.
#[derive(clap::Args, Clone, Copy, Debug)]
pub struct ProgressArgs {
    /// Seconds between two plain progress lines on stderr when it is not a terminal (a batch
    /// job's log, `nohup`, CI), where the progress bar draws nothing: `bake: 3/10 cells, 1,234
    /// sample points (1,100 of 2,048 rectangles), 00:05:02 elapsed, about 00:11:45 left`,
    /// `validate: 8,000,000/20,000,000 rays (40 %), 00:01:02 elapsed, about 00:01:33 left`. A last
    /// line (the last cell's, all the rays) is always printed. 0: a line at every report;
    /// `off`: none.
    #[arg(
        long,
        value_name = "SECS|off",
        default_value = "60",
        value_parser = parse_progress_every
    )]
    pub progress_every: ProgressEvery,
}

/// Parses `--progress-every`: seconds (0: a line whenever something moves) or `off`.
///
/// # Errors
/// Anything but `off` or a finite number of seconds ≥ 0, with what was expected.
pub fn parse_progress_every(v: &str) -> Result<ProgressEvery, String> {
    if v == "off" {
        return Ok(ProgressEvery(None));
    }
    match v.parse::<f64>() {
        Ok(s) if s >= 0.0 && s.is_finite() => Ok(ProgressEvery(Some(s))),
        _ => Err(format!(
            "expected seconds between two progress lines (e.g. 60, 0 for every cell) or `off`, \
             got {v:?}"
        )),
    }
}

/// The sampler's work so far, for lines inside long cells.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SamplerWork {
    /// Sample points rendered.
    pub points: u64,
    /// Face rectangles finished, and those of the levels begun.
    pub rects: (u64, u64),
}

impl SamplerWork {
    /// What the bake's counters hold now.
    pub fn now(p: &SamplerProgress) -> Self {
        SamplerWork {
            points: p.points.load(Ordering::Relaxed),
            rects: (
                p.rects_done.load(Ordering::Relaxed),
                p.rects_begun.load(Ordering::Relaxed),
            ),
        }
    }
}

/// What the last line said, and when.
struct State {
    /// This run's cells done (the largest count reported: workers report out of order).
    done: usize,
    /// When the last line was printed (at first, the start).
    last: Instant,
    /// The cells and sampler work the last line reported (at first, nothing done: nothing
    /// to say yet).
    printed: (usize, SamplerWork),
    /// The pace of the sampler's rectangles.
    pace: RectPace,
}

/// A bake's plain progress log (see the module docs). Shared by the workers, which report
/// finished cells, and a ticker thread, which reports sample points inside long cells.
pub struct PlainProgress {
    start: Instant,
    every: Duration,
    /// Cells of the whole bake, and those a resumed bake found already done.
    total: usize,
    resumed: usize,
    state: Mutex<State>,
}

impl PlainProgress {
    /// A log for a bake of `total` cells of which `resumed` are done already, printing at most
    /// one line per `every` seconds (0: a line whenever the count of cells or points moves).
    pub fn new(total: usize, resumed: usize, every: f64) -> Self {
        let start = Instant::now();
        PlainProgress {
            start,
            every: Duration::from_secs_f64(every),
            total,
            resumed,
            state: Mutex::new(State {
                done: 0,
                last: start,
                printed: (0, SamplerWork::default()),
                pace: RectPace::default(),
            }),
        }
    }

    /// `done` of this run's cells are finished (`work`: the sampler's so far). The last
    /// cell's line is always printed.
    pub fn cell_done(&self, done: usize, work: SamplerWork) {
        let mut s = self.state.lock().expect("not poisoned");
        s.done = s.done.max(done);
        let last_cell = self.resumed + s.done >= self.total;
        self.maybe_print(&mut s, work, last_cell);
    }

    /// Called now and then while cells run: a line when the interval has passed and the
    /// sampler's work moved.
    pub fn tick(&self, work: SamplerWork) {
        let mut s = self.state.lock().expect("not poisoned");
        self.maybe_print(&mut s, work, false);
    }

    fn maybe_print(&self, s: &mut State, work: SamplerWork, force: bool) {
        let now = Instant::now();
        let rects_left = s.pace.update(now, work.points, work.rects);
        let now_state = (s.done, work);
        if s.printed == now_state || (!force && now - s.last < self.every) {
            return;
        }
        eprintln!("{}", self.line(s.done, work, now - self.start, rects_left));
        s.last = now;
        s.printed = now_state;
    }

    /// `bake: 3/10 cells, 1,234 sample points (1,100 of 2,048 rectangles, about 00:02:10 more
    /// at this pace), 00:05:02 elapsed, about 00:11:45 left` (`rects_left`: the rectangles'
    /// estimate, [`RectPace`]).
    fn line(
        &self,
        done: usize,
        work: SamplerWork,
        elapsed: Duration,
        rects_left: Option<Duration>,
    ) -> String {
        let mut line = format!("bake: {}/{} cells", self.resumed + done, self.total);
        if work.points > 0 {
            line += &format!(", {} sample points", thousands(work.points));
        }
        let (rd, rb) = work.rects;
        if rb > 0 && rd < rb {
            line += &format!(" ({})", rectangles(work, rects_left));
        }
        line += &format!(", {} elapsed", clock(elapsed));
        let left = self.total.saturating_sub(self.resumed + done);
        if done > 0 && left > 0 {
            let eta = elapsed.mul_f64(left as f64 / done as f64);
            line += &format!(", about {} left", clock(eta));
        }
        line
    }
}

/// `validate`'s progress as plain lines: `validate: 8,000,000/20,000,000 rays (40 %), 00:01:02
/// elapsed, about 00:01:33 left`, at most one per `every` seconds (0: at every report of the
/// workers), and always when the rays are done.
pub fn plain_rays(every: f64) -> umbrasweep::validate::ProgressFn {
    use umbrasweep::validate::Progress;
    struct Rays {
        start: Instant,
        last: Instant,
        total: u64,
        done: u64,
    }
    let every = Duration::from_secs_f64(every);
    let state = Mutex::new(None::<Rays>);
    std::sync::Arc::new(move |p: Progress| {
        let mut s = state.lock().expect("not poisoned");
        let now = Instant::now();
        let force = match p {
            Progress::Start { total } => {
                *s = Some(Rays {
                    start: now,
                    last: now,
                    total,
                    done: 0,
                });
                return;
            }
            Progress::Advance(n) => {
                if let Some(r) = s.as_mut() {
                    r.done += n;
                }
                false
            }
            Progress::Finish => true,
        };
        let Some(r) = s.as_mut() else { return };
        if !force && now - r.last < every {
            return;
        }
        r.last = now;
        let elapsed = now - r.start;
        let mut line = format!(
            "validate: {}/{} rays ({:.0} %), {} elapsed",
            thousands(r.done),
            thousands(r.total),
            100.0 * r.done as f64 / r.total.max(1) as f64,
            clock(elapsed)
        );
        if r.done > 0 && r.done < r.total {
            let eta = elapsed.mul_f64((r.total - r.done) as f64 / r.done as f64);
            line += &format!(", about {} left", clock(eta));
        }
        eprintln!("{line}");
    })
}

/// `1,100 of 2,048 rectangles`, and `, about 00:02:10 more at this pace` with an estimate of
/// a second or more: what the bar and the plain lines say of the sampler's rectangles.
pub fn rectangles(work: SamplerWork, left: Option<Duration>) -> String {
    let (rd, rb) = work.rects;
    let mut s = format!("{} of {} rectangles", thousands(rd), thousands(rb));
    if let Some(d) = left.filter(|d| d.as_secs() > 0) {
        s += &format!(", about {} more at this pace", clock(d));
    }
    s
}

/// `01:02:03` (hours, minutes, seconds; days before them when there are any).
fn clock(d: Duration) -> String {
    indicatif::FormattedDuration(d).to_string()
}

/// `1234567` as `1,234,567`.
fn thousands(n: u64) -> String {
    indicatif::HumanCount(n).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_counts_read_as_a_person_writes_them() {
        assert_eq!(clock(Duration::from_millis(12_345)), "00:00:12");
        assert_eq!(clock(Duration::from_secs(302)), "00:05:02");
        assert_eq!(clock(Duration::from_secs(3723)), "01:02:03");
        assert_eq!(thousands(7), "7");
        assert_eq!(thousands(1_234), "1,234");
        assert_eq!(thousands(1_234_567), "1,234,567");
    }

    #[test]
    fn the_estimate_scales_the_time_so_far_by_the_cells_left() {
        let p = PlainProgress::new(10, 2, 60.0);
        let line = p.line(2, SamplerWork::default(), Duration::from_secs(120), None);
        assert_eq!(
            line,
            "bake: 4/10 cells, 00:02:00 elapsed, about 00:06:00 left"
        );
        let work = SamplerWork {
            points: 1_500,
            rects: (1_600, 65_536),
        };
        let line = p.line(0, work, Duration::from_secs(30), None);
        assert_eq!(
            line,
            "bake: 2/10 cells, 1,500 sample points (1,600 of 65,536 rectangles), 00:00:30 elapsed"
        );
        let line = p.line(
            0,
            work,
            Duration::from_secs(30),
            Some(Duration::from_secs(130)),
        );
        assert_eq!(
            line,
            "bake: 2/10 cells, 1,500 sample points (1,600 of 65,536 rectangles, about 00:02:10 \
             more at this pace), 00:00:30 elapsed"
        );
    }

    #[test]
    fn the_rectangles_pace_is_that_of_the_points_since_their_level_began() {
        let t = Instant::now();
        let at = |s: u64| t + Duration::from_secs(s);
        let mut pace = RectPace::default();
        // A level of 100 rectangles begins (10 done before it): nothing to go by yet.
        assert_eq!(pace.update(at(0), 0, (10, 110)), None);
        assert_eq!(pace.update(at(5), 10, (10, 110)), None, "too soon");
        // 20 points in 20 s, no chunk counted done yet: the other 80 take about 80 s.
        assert_eq!(
            pace.update(at(20), 20, (10, 110)),
            Some(Duration::from_secs(80))
        );
        // A chunk counted done ahead of the points (a probe's rectangles left unsampled):
        // what is left is what is not done.
        assert_eq!(
            pace.update(at(40), 40, (100, 110)),
            Some(Duration::from_secs(10))
        );
        // The next level's 400 begin: its own pace, from its start.
        assert_eq!(pace.update(at(50), 45, (110, 510)), None);
        assert_eq!(
            pace.update(at(70), 55, (110, 510)),
            Some(Duration::from_secs(780))
        );
        // Everything begun is done: nothing left to estimate.
        assert_eq!(pace.update(at(80), 500, (510, 510)), None);
    }

    #[test]
    fn progress_every_takes_seconds_or_off() {
        assert_eq!(parse_progress_every("off"), Ok(ProgressEvery(None)));
        assert_eq!(parse_progress_every("2.5"), Ok(ProgressEvery(Some(2.5))));
        assert!(parse_progress_every("-1").unwrap_err().contains("`off`"));
        assert!(parse_progress_every("soon").is_err());
    }
}
