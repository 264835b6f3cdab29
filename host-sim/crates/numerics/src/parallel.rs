//! Independent evaluations on all cores (std scoped threads, no thread pool): the discovery's
//! likelihood fits of several candidate models, the start points of one noise fit.

/// Threads for `n` items: the cores there are, at most one per item, at least one.
fn threads_for(n: usize) -> usize {
    std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .clamp(1, n.max(1))
}

/// `f` of every item, in order, the items split into contiguous runs over
/// [`std::thread::available_parallelism`] threads (this thread takes the first run). A panic in
/// `f` is resumed on the caller's thread.
pub fn par_map<T: Sync, U: Send>(items: &[T], f: impl Fn(&T) -> U + Sync) -> Vec<U> {
    let threads = threads_for(items.len());
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let per = items.len().div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let mut runs = items.chunks(per);
        let first = runs.next().unwrap_or(&[]);
        let handles: Vec<_> = runs
            .map(|run| s.spawn(move || run.iter().map(f).collect::<Vec<U>>()))
            .collect();
        let mut out: Vec<U> = first.iter().map(f).collect();
        for h in handles {
            out.extend(h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        }
        out
    })
}

/// `a()` and `b()` at once, `b` on a second thread when there is a second core (else one after
/// the other on this thread). A panic in either is resumed on the caller's thread.
pub fn join<A: Send, B: Send>(
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if threads_for(2) == 1 {
        let ra = a();
        return (ra, b());
    }
    std::thread::scope(|s| {
        let hb = s.spawn(b);
        let ra = a();
        let rb = hb.join().unwrap_or_else(|p| std::panic::resume_unwind(p));
        (ra, rb)
    })
}

/// [`par_map`] for items of very unequal cost: the threads take the next item as they finish
/// one (a shared counter) instead of a fixed run each, so one slow item does not leave the other
/// cores idle behind a run of quick ones. The results are in the items' order.
pub fn par_map_balanced<T: Sync, U: Send>(items: &[T], f: impl Fn(&T) -> U + Sync) -> Vec<U> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let threads = threads_for(items.len());
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let work = || {
        let mut done = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(item) = items.get(i) else {
                break done;
            };
            done.push((i, f(item)));
        }
    };
    let work = &work;
    let mut all: Vec<(usize, U)> = std::thread::scope(|s| {
        let handles: Vec<_> = (1..threads).map(|_| s.spawn(work)).collect();
        let mut all = work();
        for h in handles {
            all.extend(h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        }
        all
    });
    all.sort_unstable_by_key(|(i, _)| *i);
    all.into_iter().map(|(_, u)| u).collect()
}

/// Progress of a long parallel run as plain lines on stderr when stderr is not a terminal
/// (where the progress bars are not drawn): one line at most every [`ProgressLines::every`]
/// (a minute; `ACCOMP_PROGRESS_EVERY_S` sets another), and nothing on a terminal.
pub struct ProgressLines {
    what: String,
    unit: &'static str,
    total: usize,
    done: std::sync::atomic::AtomicUsize,
    started: std::time::Instant,
    last: std::sync::Mutex<std::time::Instant>,
    every: Option<std::time::Duration>,
}

impl ProgressLines {
    /// Counts `total` steps of `what`, in `unit`.
    pub fn new(what: String, total: usize, unit: &'static str) -> Self {
        use std::io::IsTerminal as _;
        let every = (!std::io::stderr().is_terminal()).then(Self::every);
        let now = std::time::Instant::now();
        ProgressLines {
            what,
            unit,
            total,
            done: std::sync::atomic::AtomicUsize::new(0),
            started: now,
            last: std::sync::Mutex::new(now),
            every,
        }
    }

    /// The interval between lines.
    pub fn every() -> std::time::Duration {
        let s = std::env::var("ACCOMP_PROGRESS_EVERY_S")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(60.0);
        std::time::Duration::from_secs_f64(s)
    }

    /// One step done; prints a line when the interval has passed.
    pub fn inc(&self) {
        self.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.maybe_print();
    }

    /// `done` steps done; prints a line when the interval has passed.
    pub fn set(&self, done: usize) {
        self.done.store(done, std::sync::atomic::Ordering::Relaxed);
        self.maybe_print();
    }

    fn maybe_print(&self) {
        let Some(every) = self.every else {
            return;
        };
        let Ok(mut last) = self.last.lock() else {
            return;
        };
        if last.elapsed() >= every {
            let done = self.done.load(std::sync::atomic::Ordering::Relaxed);
            *last = std::time::Instant::now();
            eprintln!(
                "{}: {done}/{} {} ({:.0} s)",
                self.what,
                self.total,
                self.unit,
                self.started.elapsed().as_secs_f64()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_the_order_of_the_items() {
        let items: Vec<u64> = (0..37).collect();
        assert_eq!(
            par_map(&items, |x| x * x),
            items.iter().map(|x| x * x).collect::<Vec<_>>()
        );
        assert!(par_map(&[] as &[u64], |x| *x).is_empty());
    }

    #[test]
    fn balanced_results_come_back_in_the_order_of_the_items_whatever_their_cost() {
        // The first items slow, the rest quick: the threads finish them out of order.
        let items: Vec<u64> = (0..41).collect();
        let f = |x: &u64| {
            if *x < 3 {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            x * x + 1
        };
        assert_eq!(
            par_map_balanced(&items, f),
            items.iter().map(f).collect::<Vec<_>>()
        );
        assert!(par_map_balanced(&[] as &[u64], |x| *x).is_empty());
    }

    #[test]
    fn join_returns_each_closures_result_in_its_place() {
        let data: Vec<u64> = (1..=100).collect();
        let (sum, max) = join(|| data.iter().sum::<u64>(), || data.iter().max().copied());
        assert_eq!((sum, max), (5050, Some(100)));
    }
}
