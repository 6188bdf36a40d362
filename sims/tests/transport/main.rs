//! The link's transport against real zenoh peers: identity and access control
//! (`security`) and subscription scopes over a zenoh router (`subscriptions`). One
//! test binary, so that zenoh's generic code is built and linked once for both.

use troupe_testkit as common;

mod security;
mod subscriptions;
