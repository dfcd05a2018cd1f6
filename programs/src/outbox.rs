//! The bounded queue of events waiting for a player.

use std::collections::VecDeque;

use petrel_ipc::EventMsg;

/// An event waiting to be sent, with the hosted program that emitted it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Queued {
    /// Index of the hosted program that sends it.
    pub host: usize,
    /// The event.
    pub msg: EventMsg,
    /// Its encoded length, measured when it was emitted.
    pub len: usize,
}

/// Events emitted while no player received them, oldest first. Holds at most `capacity`
/// events: pushing onto a full outbox drops the oldest one and hands it back to be reported.
#[derive(Debug)]
pub(crate) struct Outbox {
    queue: VecDeque<Queued>,
    capacity: usize,
}

impl Outbox {
    pub fn new(capacity: usize) -> Self {
        Outbox {
            queue: VecDeque::with_capacity(capacity.min(1024)),
            capacity,
        }
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn len(&self) -> usize {
        self.queue.len()
    }

    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    pub fn pop_front(&mut self) -> Option<Queued> {
        self.queue.pop_front()
    }

    /// Puts back at the front an event just taken with [`pop_front`](Self::pop_front) that
    /// could not be sent (the bound holds: it was in the outbox a moment ago).
    pub fn restore_front(&mut self, item: Queued) {
        self.queue.push_front(item);
    }

    /// Queues `item` at the back. When the outbox is full, the oldest event is dropped and
    /// returned (with a capacity of 0, `item` itself is).
    pub fn push(&mut self, item: Queued) -> Option<Queued> {
        if self.capacity == 0 {
            return Some(item);
        }
        let dropped = if self.queue.len() >= self.capacity {
            self.queue.pop_front()
        } else {
            None
        };
        self.queue.push_back(item);
        dropped
    }

    /// The names of the queued events, oldest first.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.queue.iter().map(|q| q.msg.name.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(n: usize) -> Queued {
        Queued {
            len: 0,
            host: 0,
            msg: EventMsg::new(format!("e{n}"), vec![]),
        }
    }

    #[test]
    fn keeps_order_and_drops_the_oldest_beyond_the_bound() {
        let mut o = Outbox::new(3);
        for n in 0..3 {
            assert!(o.push(ev(n)).is_none());
        }
        assert_eq!(o.push(ev(3)).unwrap().msg.name, "e0");
        assert_eq!(o.push(ev(4)).unwrap().msg.name, "e1");
        assert_eq!(o.names().collect::<Vec<_>>(), ["e2", "e3", "e4"]);
        assert_eq!(o.len(), 3);
        assert_eq!(o.pop_front().unwrap().msg.name, "e2");
        let e3 = o.pop_front().unwrap();
        o.restore_front(e3);
        assert_eq!(o.names().collect::<Vec<_>>(), ["e3", "e4"]);
    }

    #[test]
    fn capacity_zero_keeps_nothing() {
        let mut o = Outbox::new(0);
        assert_eq!(o.push(ev(7)).unwrap().msg.name, "e7");
        assert!(o.is_empty());
    }
}
