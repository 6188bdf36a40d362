//! zenoh key expressions of ROS 2 topics, in the two formats ROS 2 reaches zenoh by.
//!
//! - **rmw_zenoh** (ROS 2's zenoh middleware, `RMW_IMPLEMENTATION=rmw_zenoh_cpp`):
//!   `<domain_id>/<topic>/<dds type name>/<type hash>`, e.g.
//!   `0/camera/depth/image_rect_raw/sensor_msgs::msg::dds_::Image_/RIHS01_d31d…`.
//!   The topic keeps its inner slashes (only the leading one goes), so each name
//!   level is a key chunk. Liveliness tokens (graph discovery, `@ros2_lv/…`) are
//!   different: there a name is one chunk, its slashes *mangled* to `%`
//!   ([`mangle_name`]); an empty namespace or enclave is a lone `%`.
//! - **bridge** (`zenoh-bridge-ros2dds` in front of a DDS robot): the topic name
//!   without its leading slash, e.g. `camera/depth/image_rect_raw`, behind the
//!   bridge's namespace if it runs with one ([`BridgeNamespace`]: `-n /drone1` →
//!   `drone1/camera/depth/image_rect_raw`).
//!
//! Both carry the CDR payload with its encapsulation header. rmw_zenoh adds an
//! attachment ([`Attachment`](super::Attachment)).

use serde::{Deserialize, Serialize};

use super::cdr::RosMessage;

/// How ROS 2 topics map to zenoh keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WireFormat {
    /// rmw_zenoh's key format, with attachments.
    RmwZenoh,
    /// zenoh-bridge-ros2dds' key format: the topic name.
    Bridge,
}

/// A key format with its ROS domain and, for the bridge, its namespace.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KeyFormat {
    /// The wire format.
    pub format: WireFormat,
    /// `ROS_DOMAIN_ID` (the first key chunk under rmw_zenoh; the bridge leaves it out).
    pub domain_id: u32,
    /// The bridge's namespace, in front of every bridge key. rmw_zenoh keys leave it
    /// out: there a namespace is part of each topic name (the `[ros2]` table refuses
    /// one with `format = "rmw_zenoh"`).
    pub namespace: BridgeNamespace,
}

/// What a bridge namespace must be, as a [`ConfigError`](crate::ConfigError) rule.
pub const NAMESPACE_RULE: &str = "must be a namespace to put in front of zenoh keys: \
     `/name` or `/a/b` (leading `/` optional; `/` alone for none), no empty level, \
     no `*`, `$`, `#` or `?`";

/// The namespace `zenoh-bridge-ros2dds` runs with (`-n`/`--namespace`, or `namespace`
/// in its configuration file). The bridge puts it in front of the zenoh key of every
/// ROS topic it routes: under `/drone1`, `/camera/depth/image` is
/// `drone1/camera/depth/image`. The root namespace `/` (the bridge's default) adds
/// nothing.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BridgeNamespace(String);

/// A bridge namespace that cannot prefix a zenoh key.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("bridge namespace `{0}` {rule}", rule = NAMESPACE_RULE)]
pub struct NamespaceError(pub String);

impl BridgeNamespace {
    /// The root namespace: bridge keys are the bare topic names.
    pub const ROOT: BridgeNamespace = BridgeNamespace(String::new());

    /// Checks a namespace as given to the bridge: its leading `/` is optional, `/`
    /// alone is [`ROOT`](Self::ROOT); no level may be empty (`//a`, `/a/`, `""`) or
    /// hold a zenoh wildcard or reserved character (`*`, `$`, `#`, `?`).
    pub fn new(namespace: &str) -> Result<Self, NamespaceError> {
        if namespace == "/" {
            return Ok(Self::ROOT);
        }
        let stripped = namespace.strip_prefix('/').unwrap_or(namespace);
        let level_ok = |level: &str| !level.is_empty() && !level.contains(['*', '$', '#', '?']);
        if stripped.split('/').all(level_ok) {
            Ok(BridgeNamespace(stripped.to_owned()))
        } else {
            Err(NamespaceError(namespace.to_owned()))
        }
    }

    /// The key chunks it adds, without a leading or trailing `/` (`drone1`, `a/b`);
    /// empty for the root namespace.
    #[must_use]
    pub fn as_key_prefix(&self) -> &str {
        &self.0
    }
}

/// A topic name that cannot be put on zenoh.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "topic name `{0}` is not a ROS 2 name (letters, digits, `_` and `/`; no empty level, \
     no trailing `/`, no level starting with a digit)"
)]
pub struct TopicNameError(pub String);

/// Checks a ROS 2 topic name and returns it without its leading slash. Relative names
/// (no leading slash) are taken as being in the root namespace.
pub fn strip_topic(topic: &str) -> Result<&str, TopicNameError> {
    let stripped = topic.strip_prefix('/').unwrap_or(topic);
    let level_ok = |level: &str| {
        !level.is_empty()
            && !level.starts_with(|c: char| c.is_ascii_digit())
            && level.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if stripped.split('/').all(level_ok) {
        Ok(stripped)
    } else {
        Err(TopicNameError(topic.to_owned()))
    }
}

/// A name as rmw_zenoh writes it inside a liveliness token: `/` becomes `%`
/// (`/camera/depth/image` → `%camera%depth%image`), and an empty name is `%`.
#[must_use]
pub fn mangle_name(name: &str) -> String {
    if name.is_empty() {
        "%".to_owned()
    } else {
        name.replace('/', "%")
    }
}

/// The DDS type name of a ROS interface: `sensor_msgs/msg/Image` →
/// `sensor_msgs::msg::dds_::Image_`.
#[must_use]
pub fn dds_type_name(type_name: &str) -> String {
    match type_name.rsplit_once('/') {
        Some((package, name)) => format!("{}::dds_::{name}_", package.replace('/', "::")),
        None => format!("{type_name}_"),
    }
}

impl KeyFormat {
    /// The key a message of type `T` on `topic` is published on.
    pub fn topic_key<T: RosMessage>(&self, topic: &str) -> Result<String, TopicNameError> {
        self.key::<T>(topic, T::TYPE_HASH)
    }

    /// The key expression to subscribe to `topic` with: under rmw_zenoh the type hash
    /// is a wildcard, so a publisher built from another ROS release (whose hash may
    /// differ while the CDR layout is the same) is still heard.
    pub fn subscribe_key<T: RosMessage>(&self, topic: &str) -> Result<String, TopicNameError> {
        self.key::<T>(topic, "*")
    }

    fn key<T: RosMessage>(&self, topic: &str, hash: &str) -> Result<String, TopicNameError> {
        let topic = strip_topic(topic)?;
        Ok(match self.format {
            WireFormat::RmwZenoh => format!(
                "{}/{topic}/{}/{hash}",
                self.domain_id,
                dds_type_name(T::TYPE_NAME)
            ),
            WireFormat::Bridge => match self.namespace.as_key_prefix() {
                "" => topic.to_owned(),
                namespace => format!("{namespace}/{topic}"),
            },
        })
    }

    /// The key of the liveliness token that announces a publisher of `T` on `topic` to
    /// rmw_zenoh's graph (what `ros2 topic list` reads): `@ros2_lv/<domain>/<session
    /// id>/<node id>/<entity id>/MP/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/
    /// <qos>`, names mangled, QoS keep-last 10 and rmw_zenoh's default for every other
    /// policy (an empty component). Written from rmw_zenoh 0.6's design; not checked
    /// against a live rmw_zenoh graph. `None` for the bridge format (the bridge
    /// discovers DDS entities, not zenoh ones).
    pub fn publisher_liveliness_key<T: RosMessage>(
        &self,
        session_id: &str,
        entity_id: u32,
        node_name: &str,
        topic: &str,
    ) -> Result<Option<String>, TopicNameError> {
        if self.format == WireFormat::Bridge {
            return Ok(None);
        }
        let topic = strip_topic(topic)?;
        Ok(Some(format!(
            "@ros2_lv/{}/{session_id}/0/{entity_id}/MP/%/%/{node_name}/{}/{}/{}/::,10:,:,:,,",
            self.domain_id,
            mangle_name(&format!("/{topic}")),
            dds_type_name(T::TYPE_NAME),
            T::TYPE_HASH
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros2::msgs::{Image, Odometry};

    const RMW: KeyFormat = KeyFormat {
        format: WireFormat::RmwZenoh,
        domain_id: 0,
        namespace: BridgeNamespace::ROOT,
    };

    fn bridge(namespace: &str) -> KeyFormat {
        KeyFormat {
            format: WireFormat::Bridge,
            domain_id: 3,
            namespace: BridgeNamespace::new(namespace).unwrap(),
        }
    }

    #[test]
    fn rmw_zenoh_keys_keep_inner_slashes_and_carry_type_and_hash() {
        assert_eq!(
            RMW.topic_key::<Image>("/camera/depth/image_rect_raw")
                .unwrap(),
            "0/camera/depth/image_rect_raw/sensor_msgs::msg::dds_::Image_/\
             RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        let domain7 = KeyFormat {
            domain_id: 7,
            ..RMW
        };
        assert_eq!(
            domain7.subscribe_key::<Odometry>("odom").unwrap(),
            "7/odom/nav_msgs::msg::dds_::Odometry_/*"
        );
    }

    #[test]
    fn bridge_keys_are_the_topic_without_its_leading_slash() {
        let bridge = bridge("/");
        assert_eq!(
            bridge.topic_key::<Image>("/camera/depth/image").unwrap(),
            "camera/depth/image"
        );
        assert_eq!(bridge.subscribe_key::<Image>("/odom").unwrap(), "odom");
        assert_eq!(
            bridge
                .publisher_liveliness_key::<Image>("abc", 1, "troupe", "/x")
                .unwrap(),
            None
        );
    }

    #[test]
    fn bridge_keys_carry_the_bridge_namespace_in_front() {
        let drone1 = bridge("/drone1");
        assert_eq!(
            drone1.topic_key::<Image>("/camera/depth/image").unwrap(),
            "drone1/camera/depth/image"
        );
        assert_eq!(
            drone1.subscribe_key::<Odometry>("odom").unwrap(),
            "drone1/odom"
        );
        // The leading slash is optional, and a namespace may have several levels.
        assert_eq!(bridge("drone1"), drone1);
        assert_eq!(
            bridge("/team7/drone1")
                .topic_key::<Image>("/troupe/plan")
                .unwrap(),
            "team7/drone1/troupe/plan"
        );
        assert_eq!(bridge("/").namespace, BridgeNamespace::ROOT);
        for key in [
            drone1.topic_key::<Image>("/camera/depth/image").unwrap(),
            bridge("/team7/drone1")
                .subscribe_key::<Image>("/a")
                .unwrap(),
        ] {
            zenoh::key_expr::KeyExpr::try_from(key.as_str()).unwrap();
        }
        // Still no liveliness tokens: the bridge discovers DDS entities.
        assert_eq!(
            drone1
                .publisher_liveliness_key::<Image>("abc", 1, "troupe", "/x")
                .unwrap(),
            None
        );
    }

    #[test]
    fn rmw_zenoh_keys_leave_a_namespace_out() {
        let with_namespace = KeyFormat {
            namespace: BridgeNamespace::new("/drone1").unwrap(),
            ..RMW
        };
        for topic in ["/camera/depth/image", "odom"] {
            assert_eq!(
                with_namespace.topic_key::<Image>(topic).unwrap(),
                RMW.topic_key::<Image>(topic).unwrap()
            );
            assert_eq!(
                with_namespace.subscribe_key::<Image>(topic).unwrap(),
                RMW.subscribe_key::<Image>(topic).unwrap()
            );
        }
    }

    #[test]
    fn bad_bridge_namespaces_are_rejected_with_the_namespace() {
        for bad in [
            "", "//", "//a", "/a/", "a//b", "/a/*", "/**", "/a$b", "/$*", "/a#", "/a?b",
        ] {
            let err = BridgeNamespace::new(bad).unwrap_err();
            assert_eq!(err, NamespaceError(bad.to_owned()));
            assert!(err.to_string().contains(&format!("`{bad}`")), "{err}");
        }
    }

    #[test]
    fn liveliness_tokens_mangle_the_topic_into_one_chunk() {
        assert_eq!(mangle_name("/camera/depth/image"), "%camera%depth%image");
        assert_eq!(mangle_name(""), "%");
        let key = RMW
            .publisher_liveliness_key::<Image>("1f2e", 4, "troupe", "/camera/depth")
            .unwrap()
            .unwrap();
        assert!(
            key.starts_with(
                "@ros2_lv/0/1f2e/0/4/MP/%/%/troupe/%camera%depth/sensor_msgs::msg::dds_::Image_/RIHS01_"
            ),
            "{key}"
        );
    }

    #[test]
    fn bad_topic_names_are_rejected_with_the_name() {
        for bad in ["", "/", "//a", "/a/", "/a b", "/1a", "/a/*", "/a/$b"] {
            let err = RMW.topic_key::<Image>(bad).unwrap_err();
            assert_eq!(err, TopicNameError(bad.to_owned()));
            assert!(err.to_string().contains(&format!("`{bad}`")));
        }
    }

    #[test]
    fn dds_type_names_follow_the_ros_idl_mapping() {
        assert_eq!(
            dds_type_name("nav_msgs/msg/Odometry"),
            "nav_msgs::msg::dds_::Odometry_"
        );
    }
}
