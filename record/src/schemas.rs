//! The JSON Schemas of a recording's channels (MCAP schema encoding `jsonschema`).
//! Foxglove recognises its well-known types by the schema name (`foxglove.SceneUpdate`,
//! …) and plots any field of the `troupe.*` ones. Each schema states the fields that
//! [`crate::foxglove`] and the recorder write, so an independent validator can check
//! every message against its channel's schema.

use serde_json::{Value, json};

/// One schema: its name and JSON Schema document.
#[derive(Clone, Copy, Debug)]
pub struct Schema {
    /// MCAP schema name.
    pub name: &'static str,
    /// Builds the JSON Schema document.
    document: fn() -> Value,
}

impl Schema {
    /// The schema document as bytes (the MCAP schema record's data).
    #[must_use]
    pub fn data(&self) -> Vec<u8> {
        let mut doc = (self.document)();
        if let Some(object) = doc.as_object_mut() {
            object.insert("title".into(), json!(self.name));
            object.insert(
                "$schema".into(),
                json!("https://json-schema.org/draft/2020-12/schema"),
            );
        }
        doc.to_string().into_bytes()
    }
}

fn object(properties: Value) -> Value {
    let required: Vec<String> = properties
        .as_object()
        .map(|o| o.keys().cloned().collect())
        .unwrap_or_default();
    json!({"type": "object", "properties": properties, "required": required})
}

fn number() -> Value {
    json!({"type": "number"})
}

fn time() -> Value {
    object(json!({
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    }))
}

fn vector3() -> Value {
    object(json!({"x": number(), "y": number(), "z": number()}))
}

fn quaternion() -> Value {
    object(json!({"x": number(), "y": number(), "z": number(), "w": number()}))
}

fn pose() -> Value {
    object(json!({"position": vector3(), "orientation": quaternion()}))
}

fn color() -> Value {
    let c = json!({"type": "number", "minimum": 0, "maximum": 1});
    object(json!({"r": c, "g": c, "b": c, "a": c}))
}

fn array(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

fn string() -> Value {
    json!({"type": "string"})
}

fn scene_entity() -> Value {
    let any = array(json!({}));
    object(json!({
        "timestamp": time(),
        "frame_id": string(),
        "id": string(),
        "lifetime": time(),
        "frame_locked": {"type": "boolean"},
        "metadata": array(object(json!({"key": string(), "value": string()}))),
        "arrows": any,
        "cubes": any,
        "spheres": array(object(json!({"pose": pose(), "size": vector3(), "color": color()}))),
        "cylinders": any,
        "lines": array(object(json!({
            "type": {"type": "integer", "enum": [0, 1, 2]},
            "pose": pose(),
            "thickness": number(),
            "scale_invariant": {"type": "boolean"},
            "points": array(vector3()),
            "color": color(),
            "colors": array(color()),
            "indices": array(json!({"type": "integer", "minimum": 0})),
        }))),
        "triangles": array(object(json!({
            "pose": pose(),
            "points": array(vector3()),
            "color": color(),
            "colors": array(color()),
            "indices": array(json!({"type": "integer", "minimum": 0})),
        }))),
        "texts": any,
        "models": any,
    }))
}

/// `foxglove.FrameTransform`.
pub const FRAME_TRANSFORM: Schema = Schema {
    name: "foxglove.FrameTransform",
    document: || {
        object(json!({
            "timestamp": time(),
            "parent_frame_id": string(),
            "child_frame_id": string(),
            "translation": vector3(),
            "rotation": quaternion(),
        }))
    },
};

/// `foxglove.PoseInFrame`.
pub const POSE_IN_FRAME: Schema = Schema {
    name: "foxglove.PoseInFrame",
    document: || object(json!({"timestamp": time(), "frame_id": string(), "pose": pose()})),
};

/// `foxglove.SceneUpdate`.
pub const SCENE_UPDATE: Schema = Schema {
    name: "foxglove.SceneUpdate",
    document: || object(json!({"deletions": array(json!({})), "entities": array(scene_entity())})),
};

/// `foxglove.PointCloud` (`data`: base64 of the packed points).
pub const POINT_CLOUD: Schema = Schema {
    name: "foxglove.PointCloud",
    document: || {
        let count = json!({"type": "integer", "minimum": 0});
        object(json!({
            "timestamp": time(),
            "frame_id": string(),
            "pose": pose(),
            "point_stride": count,
            "fields": array(object(json!({
                "name": string(),
                "offset": count,
                "type": {"type": "integer", "minimum": 0, "maximum": 8},
            }))),
            "data": {"type": "string", "contentEncoding": "base64"},
        }))
    },
};

/// `foxglove.RawImage` (`data`: base64 of the pixels).
pub const RAW_IMAGE: Schema = Schema {
    name: "foxglove.RawImage",
    document: || {
        let count = json!({"type": "integer", "minimum": 0});
        object(json!({
            "timestamp": time(),
            "frame_id": string(),
            "width": count,
            "height": count,
            "encoding": string(),
            "step": count,
            "data": {"type": "string", "contentEncoding": "base64"},
        }))
    },
};

/// `troupe.LinkStatus`: the link actor's counters (per class offered, sent, dropped,
/// queue delay; reassembly; rejected messages), as `summary.json` reports them.
pub const LINK_STATUS: Schema = Schema {
    name: "troupe.LinkStatus",
    document: || {
        object(json!({
            "shaper": {"type": "object"},
            "reassembly": {"type": "object"},
            "rejected_messages": {"type": "integer", "minimum": 0},
            "transport": {"type": ["object", "null"]},
        }))
    },
};

/// `troupe.Sample`: one robot's row of `timeseries.csv` at a sample time.
pub const SAMPLE: Schema = Schema {
    name: "troupe.Sample",
    document: || {
        let count = json!({"type": "integer", "minimum": 0});
        object(json!({
            "time_s": number(),
            "robot": count,
            "x_m": number(),
            "y_m": number(),
            "z_m": number(),
            "yaw_rad": number(),
            "speed_mps": number(),
            "distance_m": number(),
            "frames": count,
            "team_coverage": number(),
            "team_explored_m3": number(),
            "nearest_robot_m": {"type": ["number", "null"]},
            "sent_bytes": {"type": "array", "items": count, "minItems": 4, "maxItems": 4},
            "received_bytes": count,
        }))
    },
};

/// `troupe.Coverage`: the team's explored fraction and volume at a sample time, and the
/// volume its robots re-explored (observed after a peer had, thesis §8.2.7) and observed
/// alone and their redundant flight time, summed over the robots.
pub const COVERAGE: Schema = Schema {
    name: "troupe.Coverage",
    document: || {
        let volume = json!({"type": "number", "minimum": 0});
        object(json!({
            "time_s": number(),
            "fraction": {"type": "number", "minimum": 0, "maximum": 1},
            "explored_m3": volume,
            "reexplored_m3": volume,
            "exclusive_m3": volume,
            "redundant_flight_s": {"type": "number", "minimum": 0},
        }))
    },
};

/// `troupe.VehicleStatus`: a hardware robot's vehicle driver at each of its status
/// messages (2 Hz and on every change): armed, mode, whether the pilot handed control
/// over, why it holds, the setpoint rate and the heartbeat's age.
pub const VEHICLE_STATUS: Schema = Schema {
    name: "troupe.VehicleStatus",
    document: || {
        let count = json!({"type": "integer", "minimum": 0});
        object(json!({
            "armed": {"type": "boolean"},
            "mode": {"type": "string"},
            "in_control": {"type": "boolean"},
            "hold": {"type": "string"},
            "setpoint_rate_hz": {"type": "number", "minimum": 0},
            "heartbeat_age_s": {"type": ["number", "null"]},
            "heartbeat_lost": {"type": "boolean"},
            "setpoints": count,
            "holds": count,
        }))
    },
};

/// `troupe.MissionStatus`: a robot's mission at its first planning round and at each
/// change of phase (exploring, returning, home): when exploring ended and why, when
/// the robot was home, the return's time and distance, and home.
pub const MISSION_STATUS: Schema = Schema {
    name: "troupe.MissionStatus",
    document: || {
        let seconds = json!({"type": ["number", "null"], "minimum": 0});
        object(json!({
            "phase": {"enum": ["exploring", "returning", "home"]},
            "idle": {"type": "boolean"},
            "ended_s": seconds,
            "end": {"enum": ["explored", "commanded", null]},
            "home_s": seconds,
            "return_s": seconds,
            "return_distance_m": {"type": "number", "minimum": 0},
            "home_gap_m": seconds,
            "home_m": {"type": ["array", "null"], "items": number(), "minItems": 3, "maxItems": 3},
        }))
    },
};

/// Every schema a recording may use.
pub const ALL: [Schema; 10] = [
    FRAME_TRANSFORM,
    POSE_IN_FRAME,
    SCENE_UPDATE,
    POINT_CLOUD,
    RAW_IMAGE,
    LINK_STATUS,
    SAMPLE,
    COVERAGE,
    VEHICLE_STATUS,
    MISSION_STATUS,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_a_titled_object_schema() {
        for schema in ALL {
            let doc: Value = serde_json::from_slice(&schema.data()).expect("valid JSON");
            assert_eq!(doc["title"], schema.name);
            assert_eq!(doc["type"], "object");
            assert!(!doc["required"].as_array().expect("required").is_empty());
        }
    }
}
