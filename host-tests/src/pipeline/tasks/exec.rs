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
//! task storage. Both must be `'static` for embassy, so they are leaked: a few
//! hundred bytes per task and run. The tasks' futures themselves are dropped by
//! the executor when they return, which the graph makes them do at the end of a
//! run.

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
