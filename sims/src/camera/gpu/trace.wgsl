// Depth + intensity camera: one invocation per pixel sphere-traces the world's field in
// f32 and writes (z-depth, intensity), or (-1, 0) for no return. A port of
// `camera/render.rs` (trace, refine, shade) and of the worlds' `sdf_m`, `safe_step_m`,
// `normal` and `albedo`; noise and dropouts are applied on the CPU afterwards.
//
// The host prepends the constants HIT_EPS_M, MAX_TRACE_STEPS, OVER_RELAXATION,
// MIN_REFINE_COS, LIGHT_HALF_DISTANCE_M and NORMAL_STEP_M from the Rust sources.

struct Scene {
    // geometry kind (0 boxes, 1 cave), albedo kind, item count, offset of the cell items
    kind: vec4<u32>,
    // cave grid corner xyz, cell edge
    grid_origin: vec4<f32>,
    // cave grid cells xyz, offset of the noise permutation tables
    grid_dims: vec4<u32>,
    // cave roughness amplitude, wavelength, Lipschitz bound, rock clamp
    cave: vec4<f32>,
    // box interior corners (xyz)
    interior_min: vec4<f32>,
    interior_max: vec4<f32>,
    // checker square edge, even and odd reflectance
    albedo: vec4<f32>,
}

struct Pose {
    // camera position xyz, range_m
    origin: vec4<f32>,
    // columns of the body-to-world rotation
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    // fx, fy, cx, cy
    intr: vec4<f32>,
    // width, height
    size: vec4<u32>,
}

@group(0) @binding(0) var<uniform> scene: Scene;
@group(0) @binding(1) var<uniform> pose: Pose;
// Cave cell starts, cave cell items, then three doubled permutation tables.
@group(0) @binding(2) var<storage, read> words: array<u32>;
// Cave primitives (3 per primitive) or solid boxes (2 per box).
@group(0) @binding(3) var<storage, read> items: array<vec4<f32>>;
// Three lattice value tables of 256 entries.
@group(0) @binding(4) var<storage, read> lattice_values: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_px: array<vec2<f32>>;

// Noise slots: 0 wall roughness, 1 texture grain, 2 strata.
const PERIOD: u32 = 256u;

fn perm(slot: u32, i: u32) -> u32 {
    return words[scene.grid_dims.w + slot * 2u * PERIOD + i];
}

fn lattice(slot: u32, i: u32) -> f32 {
    return lattice_values[slot * PERIOD + perm(slot, i)];
}

fn wrap_period(f: f32) -> u32 {
    let i = i32(f) % i32(PERIOD);
    return u32(select(i, i + i32(PERIOD), i < 0));
}

fn fade(t: f32) -> f32 {
    return t * t * (3.0 - 2.0 * t);
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}

// `ValueNoise::value`.
fn noise_value(slot: u32, p: vec3<f32>) -> f32 {
    let f = floor(p);
    let x = wrap_period(f.x);
    let y = wrap_period(f.y);
    let z = wrap_period(f.z);
    let u = fade(p.x - f.x);
    let v = fade(p.y - f.y);
    let w = fade(p.z - f.z);
    let a = perm(slot, x) + y;
    let b = perm(slot, x + 1u) + y;
    let aa = perm(slot, a) + z;
    let ab = perm(slot, a + 1u) + z;
    let ba = perm(slot, b) + z;
    let bb = perm(slot, b + 1u) + z;
    let x00 = lerp(lattice(slot, aa), lattice(slot, ba), u);
    let x10 = lerp(lattice(slot, ab), lattice(slot, bb), u);
    let x01 = lerp(lattice(slot, aa + 1u), lattice(slot, ba + 1u), u);
    let x11 = lerp(lattice(slot, ab + 1u), lattice(slot, bb + 1u), u);
    return lerp(lerp(x00, x10, v), lerp(x01, x11, v), w);
}

// `ValueNoise::fbm` with 3 octaves.
fn fbm3(slot: u32, p: vec3<f32>) -> f32 {
    var sum = 0.0;
    var amp = 1.0;
    var norm = 0.0;
    var q = p;
    for (var i = 0u; i < 3u; i++) {
        sum += amp * noise_value(slot, q);
        norm += amp;
        amp *= 0.5;
        q = q * 2.0 + vec3<f32>(17.3, -9.1, 4.7);
    }
    return sum / norm;
}

// ---- cave (`world/cave`) ----

fn primitive_free_m(i: u32, p: vec3<f32>) -> f32 {
    // x: 0 capsule / 1 chamber, y: radius, z: 1/|ab|² or floor height
    let head = items[3u * i];
    let a = items[3u * i + 1u].xyz;
    if head.x < 0.5 {
        let ab = items[3u * i + 2u].xyz;
        let ap = p - a;
        let t = clamp(dot(ap, ab) * head.z, 0.0, 1.0);
        return head.y - length(ap - ab * t);
    }
    return min(head.y - length(p - a), p.z - head.z);
}

// `Field::base_m`.
fn cave_base_m(p: vec3<f32>) -> f32 {
    var best = -scene.cave.w;
    let f = floor((p - scene.grid_origin.xyz) / scene.grid_origin.w);
    let dims = vec3<f32>(scene.grid_dims.xyz);
    if any(f < vec3<f32>(0.0)) || any(f >= dims) {
        return best;
    }
    let c = vec3<u32>(f);
    let cell = c.x + scene.grid_dims.x * (c.y + scene.grid_dims.y * c.z);
    let end = words[cell + 1u];
    for (var k = words[cell]; k < end; k++) {
        best = max(best, primitive_free_m(words[scene.kind.w + k], p));
    }
    return best;
}

fn cave_roughness_m(p: vec3<f32>) -> f32 {
    return scene.cave.x * noise_value(0u, p / scene.cave.y);
}

// `CaveWorld::safe_step_m`.
fn cave_safe_step_m(p: vec3<f32>) -> f32 {
    let base = cave_base_m(p);
    let a = scene.cave.x;
    if base > 3.0 * a {
        return base - a;
    }
    let near = (base + cave_roughness_m(p)) / scene.cave.z;
    return max(near, base - a);
}

// ---- boxes (`world/solids`, `BoxRoom`) ----

fn inside(lo: vec3<f32>, hi: vec3<f32>, p: vec3<f32>) -> bool {
    return all(p >= lo) && all(p <= hi);
}

fn inner_m(lo: vec3<f32>, hi: vec3<f32>, p: vec3<f32>) -> f32 {
    let d = min(p - lo, hi - p);
    return min(d.x, min(d.y, d.z));
}

fn outside_m(lo: vec3<f32>, hi: vec3<f32>, p: vec3<f32>) -> f32 {
    return length(max(max(lo - p, p - hi), vec3<f32>(0.0)));
}

fn boxes_sdf_m(p: vec3<f32>) -> f32 {
    let lo = scene.interior_min.xyz;
    let hi = scene.interior_max.xyz;
    if !inside(lo, hi, p) {
        return -outside_m(lo, hi, p);
    }
    var best = inner_m(lo, hi, p);
    for (var i = 0u; i < scene.kind.z; i++) {
        let s_lo = items[2u * i].xyz;
        let s_hi = items[2u * i + 1u].xyz;
        if inside(s_lo, s_hi, p) {
            best = min(best, -inner_m(s_lo, s_hi, p));
        } else {
            best = min(best, outside_m(s_lo, s_hi, p));
        }
    }
    return best;
}

// ---- the world ----

fn sdf_m(p: vec3<f32>) -> f32 {
    if scene.kind.x == 1u {
        return cave_base_m(p) + cave_roughness_m(p);
    }
    return boxes_sdf_m(p);
}

fn safe_step_m(p: vec3<f32>) -> f32 {
    if scene.kind.x == 1u {
        return cave_safe_step_m(p);
    }
    return boxes_sdf_m(p);
}

// `CaveWorld::normal` (tetrahedron) or `World::normal` (central differences).
fn normal(p: vec3<f32>) -> vec3<f32> {
    let h = NORMAL_STEP_M;
    var g: vec3<f32>;
    if scene.kind.x == 1u {
        let k0 = vec3<f32>(1.0, -1.0, -1.0);
        let k1 = vec3<f32>(-1.0, -1.0, 1.0);
        let k2 = vec3<f32>(-1.0, 1.0, -1.0);
        let k3 = vec3<f32>(1.0, 1.0, 1.0);
        g = k0 * sdf_m(p + k0 * h) + k1 * sdf_m(p + k1 * h) + k2 * sdf_m(p + k2 * h)
            + k3 * sdf_m(p + k3 * h);
    } else {
        let ex = vec3<f32>(h, 0.0, 0.0);
        let ey = vec3<f32>(0.0, h, 0.0);
        let ez = vec3<f32>(0.0, 0.0, h);
        g = vec3<f32>(sdf_m(p + ex) - sdf_m(p - ex), sdf_m(p + ey) - sdf_m(p - ey),
            sdf_m(p + ez) - sdf_m(p - ez));
    }
    let n = length(g);
    if n <= 1e-12 {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return g / n;
}

// The worlds' `albedo`, by kind.
fn albedo(p: vec3<f32>) -> f32 {
    switch scene.kind.y {
        case 0u: {
            // BoxRoom: checkerboard.
            let f = floor(p / scene.albedo.x);
            let s = i32(f.x) + i32(f.y) + i32(f.z);
            return select(scene.albedo.z, scene.albedo.y, (s % 2) == 0);
        }
        case 1u: {
            // CaveWorld: grain and warped strata.
            let grain = fbm3(1u, p / 0.35);
            let warp = noise_value(2u, p / 3.0);
            let bands = sin(2.0 * 3.14159265358979 * p.z / 0.8 + 2.5 * warp);
            return clamp(0.5 + 0.28 * grain + 0.17 * bands, 0.05, 1.0);
        }
        case 2u: {
            // Warehouse: grain and beams (Rust's `fract` keeps the sign).
            let grain = fbm3(1u, p / 0.3);
            let s = p.z / 1.5;
            let beams = select(0.0, 0.25, s - trunc(s) < 0.08);
            return clamp(0.45 + 0.25 * grain + beams, 0.05, 1.0);
        }
        case 3u: {
            // OpenField: darker ground.
            let grain = fbm3(1u, p / 0.5);
            let base = select(0.55, 0.35, p.z < 0.05);
            return clamp(base + 0.3 * grain, 0.05, 1.0);
        }
        default: {
            // OpeningScene: bricks.
            let grain = fbm3(1u, p / 0.25);
            let k = i32(floor(p.z / 0.3)) + i32(floor(p.y / 0.6));
            let bricks = select(-0.1, 0.1, (k % 2) == 0);
            return clamp(0.5 + 0.25 * grain + bricks, 0.05, 1.0);
        }
    }
}

// `render::trace`: the ray length of the hit and the normal found before refining, or
// a negative length.
fn trace(origin: vec3<f32>, dir: vec3<f32>, t_max: f32) -> vec4<f32> {
    let none = vec4<f32>(-1.0, 0.0, 0.0, 0.0);
    var omega = OVER_RELAXATION;
    var t = 0.0;
    var radius = safe_step_m(origin);
    for (var i = 0u; i < MAX_TRACE_STEPS; i++) {
        if radius < HIT_EPS_M {
            let p = origin + dir * t;
            let n = normal(p);
            let cos_inc = max(-dot(n, dir), MIN_REFINE_COS);
            let t_hit = max(t + sdf_m(p) / cos_inc, 0.0);
            if t_hit > t_max {
                return none;
            }
            return vec4<f32>(t_hit, n);
        }
        if t + radius > t_max {
            return none;
        }
        let t_try = t + omega * radius;
        let r_try = safe_step_m(origin + dir * t_try);
        if omega > 1.0 && r_try < (omega - 1.0) * radius {
            omega = 1.0;
            t += radius;
            radius = safe_step_m(origin + dir * t);
        } else {
            t = t_try;
            radius = r_try;
        }
    }
    return none;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = pose.size.x;
    if gid.x >= width || gid.y >= pose.size.y {
        return;
    }
    let u = f32(gid.x) + 0.5;
    let v = f32(gid.y) + 0.5;
    let unit_depth = vec3<f32>(1.0, -(u - pose.intr.z) / pose.intr.x, -(v - pose.intr.w) / pose.intr.y);
    let cos_axis = 1.0 / length(unit_depth);
    let body = unit_depth * cos_axis;
    let dir = pose.rot0.xyz * body.x + pose.rot1.xyz * body.y + pose.rot2.xyz * body.z;
    let origin = pose.origin.xyz;
    let hit = trace(origin, dir, pose.origin.w / cos_axis);
    let t = hit.x;
    var result = vec2<f32>(-1.0, 0.0);
    if t >= 0.0 {
        let p = origin + dir * t;
        let lambert = max(-dot(hit.yzw, dir), 0.0);
        let falloff = 1.0 / (1.0 + (t / LIGHT_HALF_DISTANCE_M) * (t / LIGHT_HALF_DISTANCE_M));
        result = vec2<f32>(t * cos_axis, clamp(albedo(p) * lambert * falloff, 0.0, 1.0));
    }
    out_px[gid.y * width + gid.x] = result;
}
