//! Writes one valid encoded envelope per payload kind into a corpus folder, so the
//! fuzzer starts from real messages: `cargo +nightly run --example seed_corpus -- corpus/envelope_decode`.

use std::path::PathBuf;

use troupe_comms::wire::{
    self, CellChange, Component3, Component4, Envelope, GridChangeSet, GridDims, Heartbeat,
    Keyframe, Mixture, Odometry, Payload, Plan, PlanKnot, SensorPose, UserMessage, Class,
};

fn keyframe(mixture: Mixture) -> Payload {
    Payload::Keyframe(Keyframe {
        keyframe_id: 3,
        sensor_pose: SensorPose {
            position_m: [1.0, 2.0, 1.5],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        support_size: 19_200,
        mixture,
    })
}

fn payloads() -> Vec<Payload> {
    let spatial = Mixture::Spatial(vec![
        Component3 {
            mean: [0.0, 1.0, 2.0],
            covariance: [0.01, 0.001, 0.0, 0.02, 0.0, 0.03],
            weight: 0.25,
        },
        Component3 {
            mean: [3.0, -1.0, 0.5],
            covariance: [0.02, 0.0, 0.0, 0.02, 0.0, 0.02],
            weight: 0.75,
        },
    ]);
    let spatial_intensity = Mixture::SpatialIntensity(vec![Component4 {
        mean: [0.0, 1.0, 2.0, 0.5],
        covariance: [0.01, 0.001, 0.0, 0.0005, 0.02, 0.001, 0.0, 0.015, 0.0, 0.01],
        weight: 1.0,
    }]);
    let mut out = vec![
        Payload::Odometry(Odometry {
            position_m: [1.0, -2.0, 0.5],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            velocity_mps: [0.5, 0.0, 0.0],
        }),
        Payload::Heartbeat(Heartbeat { uptime_s: 12.5 }),
        Payload::Plan(Plan {
            plan_id: 9,
            priority: 2,
            start_ns: 5_000_000_000,
            knots: (0..4)
                .map(|i| PlanKnot {
                    t_s: i as f32 * 0.1,
                    position_m: [i as f32 * 0.2, 0.0, 1.0],
                    yaw_rad: 0.1,
                })
                .collect(),
        }),
        Payload::GridChanges(GridChangeSet {
            dims: GridDims {
                width: 4,
                height: 4,
                length: 2,
            },
            origin_m: [-1.0, -1.0, 0.0],
            changes: vec![
                CellChange {
                    index: 1,
                    log_odds: 0.8,
                },
                CellChange {
                    index: 7,
                    log_odds: -0.4,
                },
            ],
        }),
    ];
    for (class, name, to, body) in [
        (Class::Plan, "artifacts/report", None, vec![1, 2, 3, 4, 5, 6, 7, 8]),
        (Class::Bulk, "gas/reading", Some(0), vec![]),
    ] {
        out.push(Payload::User(UserMessage {
            class,
            name: name.into(),
            version: 1,
            to,
            body,
        }));
    }
    for mixture in [spatial, spatial_intensity] {
        if let Ok(compact) = mixture.compact() {
            out.push(keyframe(compact));
        }
        out.push(keyframe(mixture));
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: seed_corpus <corpus folder>")?,
    );
    std::fs::create_dir_all(&dir)?;
    for (index, payload) in payloads().into_iter().enumerate() {
        let envelope = Envelope::new(1, 2, index as u64, 1_000_000_000, payload);
        let bytes = wire::encode(&envelope)?;
        std::fs::write(dir.join(format!("seed-{index:02}")), bytes)?;
    }
    Ok(())
}
