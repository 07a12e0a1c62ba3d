//! One embassy-executor per task-graph run, polled by the bench.
//!
//! The firmware runs its tasks on embassy-executor's thread and interrupt
//! executors; both wrap `embassy_executor::raw::Executor`, and so does this one.
//! The platform executors (the std one included) sleep when no task is ready and
//! wake on the pender. In a simulation, "no task is ready" is exactly when the
//! simulated clock must move, which only the bench can do, so the bench polls the
//! raw executor itself ([`SimExecutor::settle`]) and the pender only raises a
//! flag. No `platform-*` feature is enabled for that reason: a platform brings
//! its own `__pender`.
//!
//! Tests run in parallel threads, so each run has its own executor and its own
//! task storage. Both must be `'static` for embassy, so they are leaked: under
//! 2 KB per run for the graph's four tasks (their big state is boxed). What the
//! tasks' futures own is dropped by the executor when they return, which the
//! graph makes them do at the end of a run.

use core::future::Future;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::raw::{Executor, TaskStorage};
use embassy_executor::SpawnError;

/// The pender of every executor in this program, all made by [`SimExecutor::new`]:
/// `context` is that executor's leaked "pended" flag.
///
/// embassy calls it when a task becomes ready while none was (from a waker, on
/// this thread). Polling from here is forbidden (`poll` must not re-enter); the
/// bench sees the flag and polls.
// SAFETY: this crate defines no other `__pender`, and no embassy platform
// feature (which would define one) is enabled for it (see Cargo.toml).
#[unsafe(export_name = "__pender")]
fn pender(context: *mut ()) {
    // SAFETY: every executor is created by `SimExecutor::new`, whose context is a
    // pointer to a leaked, never freed `AtomicBool`.
    let pended = unsafe { &*context.cast_const().cast::<AtomicBool>() };
    pended.store(true, Ordering::Release);
}

/// An embassy raw executor and its "pended" flag, both for the life of the program.
pub(super) struct SimExecutor {
    executor: &'static Executor,
    pended: &'static AtomicBool,
}

impl SimExecutor {
    /// A new executor with no tasks.
    pub(super) fn new() -> SimExecutor {
        let pended: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
        let context = core::ptr::from_ref(pended).cast_mut().cast::<()>();
        let executor = Box::leak(Box::new(Executor::new(context)));
        SimExecutor { executor, pended }
    }

    /// Spawns `task` in its own (leaked) storage; it runs at the next
    /// [`SimExecutor::settle`].
    pub(super) fn spawn<F: Future<Output = ()> + 'static>(
        &self,
        task: F,
    ) -> Result<(), SpawnError> {
        let storage: &'static TaskStorage<F> = Box::leak(Box::new(TaskStorage::new()));
        let token = storage.spawn(move || task)?;
        self.executor.spawner().spawn(token);
        Ok(())
    }

    /// Polls until no task is ready (every task waits for a wake), at most
    /// `max_polls` times; returns the number of polls, or `Err(max_polls)` if
    /// tasks were still waking each other.
    pub(super) fn settle(&self, max_polls: u32) -> Result<u32, u32> {
        for polls in 0..max_polls {
            if !self.pended.swap(false, Ordering::AcqRel) {
                return Ok(polls);
            }
            // SAFETY: `poll` is only called here, never from the pender, and the
            // executor is not `Send`, so this is the thread that created it; a
            // task being polled cannot reach this `SimExecutor` (the graph does
            // not hand it out), so `poll` is not re-entered.
            unsafe { self.executor.poll() };
        }
        if self.pended.load(Ordering::Acquire) {
            Err(max_polls)
        } else {
            Ok(max_polls)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::Cell;
    use embassy_futures::yield_now;
    use std::rc::Rc;

    #[test]
    fn settles_once_every_task_has_returned_or_waits() {
        let exec = SimExecutor::new();
        let done = Rc::new(Cell::new(0));
        for yields in 0..3 {
            let done = Rc::clone(&done);
            let task = async move {
                for _ in 0..yields {
                    yield_now().await;
                }
                done.set(done.get() + 1);
            };
            assert!(exec.spawn(task).is_ok());
        }
        // A task that waits for a wake that never comes does not keep it busy.
        assert!(exec.spawn(core::future::pending::<()>()).is_ok());
        let polls = exec.settle(100);
        assert!(matches!(polls, Ok(3..=4)), "{polls:?}");
        assert_eq!(done.get(), 3);
        assert_eq!(exec.settle(100), Ok(0));
    }

    #[test]
    fn tasks_that_keep_waking_are_reported() {
        let exec = SimExecutor::new();
        let spin = async {
            loop {
                yield_now().await;
            }
        };
        assert!(exec.spawn(spin).is_ok());
        assert_eq!(exec.settle(50), Err(50));
    }

    #[test]
    fn executors_in_parallel_threads_are_independent() {
        let runs: Vec<_> = (1..=4u32)
            .map(|n| {
                std::thread::spawn(move || {
                    let exec = SimExecutor::new();
                    let count = Rc::new(Cell::new(0u32));
                    let c = Rc::clone(&count);
                    let task = async move {
                        for _ in 0..n * 10 {
                            c.set(c.get() + 1);
                            yield_now().await;
                        }
                    };
                    exec.spawn(task).map_err(|e| e.to_string())?;
                    let polls = exec.settle(1_000).map_err(|p| format!("busy after {p}"))?;
                    Ok::<_, String>((polls, count.get()))
                })
            })
            .collect();
        for (n, run) in (1..=4u32).zip(runs) {
            let r = run.join().map_err(|_| "thread panicked");
            assert_eq!(r, Ok(Ok((n * 10 + 1, n * 10))));
        }
    }
}
