//! Per-sensor work on rayon's pool, in order.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

/// Maps `f` over `items` on rayon's pool, keeping the order.
pub(crate) fn parallel_map<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    parallel_map_with(items, |_: &mut (), item| f(item))
}

/// [`parallel_map`] where each worker keeps its own `S` (working memory, say) from item to item,
/// made with `S::default()` and dropped when its items are done.
///
/// As many workers as the pool has threads (at most one per item) are spawned into a rayon
/// scope, so no thread is started here and a batch's pool bounds the cores a take uses. Each
/// worker takes the next item not yet taken when it finishes one, rather than a share dealt out
/// first: items do not cost the same (a sensor fused from its rest, another through VQF's
/// passes), and on a shared machine one thread can be held up, so a fixed share can leave a core
/// idle while the other works through the rest of its own. (rayon's `map_init` would make a new
/// `S` for each piece of work it splits off, not one per worker.)
pub(crate) fn parallel_map_with<T: Send, R: Send, S: Default>(
    items: Vec<T>,
    f: impl Fn(&mut S, T) -> R + Sync,
) -> Vec<R> {
    let workers = rayon::current_num_threads().min(items.len().max(1));
    if workers <= 1 {
        let mut state = S::default();
        return items.into_iter().map(|t| f(&mut state, t)).collect();
    }
    let slots: Vec<Mutex<Option<T>>> = items.into_iter().map(|t| Mutex::new(Some(t))).collect();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, R)>> = Mutex::new(Vec::with_capacity(slots.len()));
    rayon::scope(|scope| {
        let (f, slots, next, results) = (&f, &slots, &next, &results);
        for _ in 0..workers {
            scope.spawn(move |_| {
                let mut state = S::default();
                let mut done = Vec::new();
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(slot) = slots.get(i) else {
                        break;
                    };
                    let item = slot
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .take()
                        .expect("each item is taken once");
                    done.push((i, f(&mut state, item)));
                }
                results
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .append(&mut done);
            });
        }
    });
    let mut results = results.into_inner().unwrap_or_else(PoisonError::into_inner);
    results.sort_by_key(|(i, _)| *i);
    results.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn parallel_map_keeps_the_order_and_takes_each_item_once() {
        let calls = AtomicUsize::new(0);
        // Each worker's state counts the items it took.
        let out = parallel_map_with((0..500u64).collect(), |taken: &mut usize, x| {
            calls.fetch_add(1, Ordering::Relaxed);
            *taken += 1;
            x * x
        });
        assert_eq!(out, (0..500u64).map(|x| x * x).collect::<Vec<_>>());
        assert_eq!(calls.load(Ordering::Relaxed), 500);
        assert!(parallel_map(Vec::<u8>::new(), |x| x).is_empty());
    }

    #[test]
    fn a_slow_item_leaves_the_rest_to_the_other_workers() {
        if rayon::current_num_threads() < 2 {
            return;
        }
        // The first item waits until every other item is done: with shares dealt out first,
        // its worker would own half of them and wait for itself until the deadline.
        let others_done = AtomicUsize::new(0);
        let n = 200;
        let out = parallel_map((0..n).collect(), |i: usize| {
            if i == 0 {
                let deadline = Instant::now() + Duration::from_secs(10);
                while others_done.load(Ordering::Acquire) < n - 1 {
                    if Instant::now() > deadline {
                        return false;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            } else {
                others_done.fetch_add(1, Ordering::Release);
            }
            true
        });
        assert!(
            out[0],
            "the other items were not taken by the other workers"
        );
        assert!(out.iter().all(|&done| done));
    }

    #[test]
    fn runs_on_the_callers_pool() {
        // In a pool of one thread there is one worker: the items run in order on it.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let order = Mutex::new(Vec::new());
        pool.install(|| {
            parallel_map((0..50).collect(), |i: i32| order.lock().unwrap().push(i));
        });
        assert_eq!(order.into_inner().unwrap(), (0..50).collect::<Vec<_>>());
    }
}
