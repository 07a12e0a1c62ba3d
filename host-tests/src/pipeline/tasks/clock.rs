//! Simulated time for one task-graph run, with the wakers a real executor needs.
//!
//! `embassy-time`'s mock driver is not used: its clock is one global, which tests
//! running in parallel threads would share.

use core::cell::{Cell, RefCell};
use core::future::poll_fn;
use core::task::{Poll, Waker};

/// Tasks to wake, each once.
#[derive(Debug, Default)]
pub(super) struct Wakers(RefCell<Vec<Waker>>);

impl Wakers {
    /// Adds `waker` unless it would wake a task already in the list.
    pub(super) fn register(&self, waker: &Waker) {
        let mut list = self.0.borrow_mut();
        if !list.iter().any(|w| w.will_wake(waker)) {
            list.push(waker.clone());
        }
    }

    /// Wakes every registered task, in registration order, and forgets them.
    pub(super) fn wake_all(&self) {
        let list = core::mem::take(&mut *self.0.borrow_mut());
        for w in list {
            w.wake();
        }
    }
}

/// The simulated time, ns. Only the bench moves it, and only forward.
///
/// Tasks wait either for any change ([`SimClock::changed`]: the bridge, which
/// runs its output clocks up to every new time) or for a time
/// ([`SimClock::at`]: a timer, like `embassy_time::Timer::at`). A timer's time
/// is also a point the bench must stop at ([`SimClock::next_timer`]), so a
/// periodic task runs at each of its periods, not once per jump of the clock.
#[derive(Debug, Default)]
pub struct SimClock {
    now: Cell<u64>,
    /// Tasks waiting for any change.
    on_change: Wakers,
    /// Tasks waiting for a time: (time ns, waker).
    timers: RefCell<Vec<(u64, Waker)>>,
}

impl SimClock {
    /// The current time, ns.
    pub fn now(&self) -> u64 {
        self.now.get()
    }

    /// The earliest time a task waits for, if any.
    pub(super) fn next_timer(&self) -> Option<u64> {
        self.timers.borrow().iter().map(|&(t, _)| t).min()
    }

    /// Moves the clock to `t_ns` (never back) and wakes the tasks that waited
    /// for a change, then those whose time has come.
    pub(super) fn advance(&self, t_ns: u64) {
        if t_ns <= self.now.get() {
            return;
        }
        self.now.set(t_ns);
        self.on_change.wake_all();
        let due: Vec<Waker> = {
            let mut timers = self.timers.borrow_mut();
            let (due, later) = core::mem::take(&mut *timers)
                .into_iter()
                .partition(|&(t, _)| t <= t_ns);
            *timers = later;
            due.into_iter().map(|(_, w)| w).collect()
        };
        for w in due {
            w.wake();
        }
    }

    /// Resolves once the clock reads something other than `seen`.
    pub async fn changed(&self, seen: u64) {
        poll_fn(|cx| {
            if self.now.get() != seen {
                Poll::Ready(())
            } else {
                self.on_change.register(cx.waker());
                Poll::Pending
            }
        })
        .await
    }

    /// Resolves once the clock has reached `t_ns`.
    pub async fn at(&self, t_ns: u64) {
        poll_fn(|cx| {
            if self.now.get() >= t_ns {
                return Poll::Ready(());
            }
            let mut timers = self.timers.borrow_mut();
            if !timers
                .iter()
                .any(|(t, w)| *t == t_ns && w.will_wake(cx.waker()))
            {
                timers.push((t_ns, cx.waker().clone()));
            }
            Poll::Pending
        })
        .await
    }
}
