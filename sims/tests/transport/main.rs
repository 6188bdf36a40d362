//! The link's transport against real zenoh peers: identity and access control
//! (`security`) and subscription scopes over a zenoh router (`subscriptions`). One
//! test binary, so that zenoh's generic code is built and linked once for both.

use std::time::{Duration, Instant};

use troupe_testkit as common;

/// Polls `done` every `poll` until it holds; fails naming `what` after `within`.
fn wait_for(what: &str, within: Duration, poll: Duration, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < within, "timed out waiting for {what}");
        std::thread::sleep(poll);
    }
}

mod security;
mod subscriptions;
