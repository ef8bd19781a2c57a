// The wgpu backend's shader. Vertices arrive in the camera frame (x right, y down, z forward),
// already culled and shaded per face by the CPU, exactly as the software rasterizer sees them.

struct Uniforms {
    // 2 fx / W, 2 cx / W - 1, -2 fy / H, 1 - 2 cy / H
    proj: vec4<f32>,
    // near plane, unused x3
    near: vec4<f32>,
    // camera pose in the world (column-major)
    X_WC: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VertexIn {
    @location(0) p_C: vec3<f32>,
    @location(1) color: vec3<f32>,
    @location(2) object: u32,
    @location(3) texture: f32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) p_C: vec3<f32>,
    @location(1) @interpolate(flat) color: vec3<f32>,
    @location(2) @interpolate(flat) object: u32,
    @location(3) @interpolate(flat) texture: f32,
};

@vertex
fn vs(v: VertexIn) -> VertexOut {
    var o: VertexOut;
    // Reversed depth: z_ndc = near / z, clipped at z = near, compared with GREATER.
    o.clip = vec4<f32>(
        u.proj.x * v.p_C.x + u.proj.y * v.p_C.z,
        u.proj.z * v.p_C.y + u.proj.w * v.p_C.z,
        u.near.x,
        v.p_C.z,
    );
    o.p_C = v.p_C;
    o.color = v.color;
    o.object = v.object;
    o.texture = v.texture;
    return o;
}

fn lattice_noise(q: vec3<i32>) -> f32 {
    var h = (bitcast<u32>(q.x) * 0x8da6b343u) ^ (bitcast<u32>(q.y) * 0xd8163841u)
        ^ (bitcast<u32>(q.z) * 0xcb1ab31fu);
    h = h ^ (h >> 13u);
    h = h * 0x5bd1e995u;
    h = h ^ (h >> 15u);
    return f32(h & 0xffffu) / 65536.0;
}

fn texture_factor(p: vec3<f32>, amplitude: f32) -> f32 {
    let n = 0.6 * lattice_noise(vec3<i32>(floor(p / 0.03))) + 0.4 * lattice_noise(vec3<i32>(floor(p / 0.15)));
    return 1.0 + amplitude * (n - 0.5) * 2.0;
}

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) depth: f32,
    @location(2) object: u32,
};

@fragment
fn fs(i: VertexOut) -> FragmentOut {
    var c = i.color;
    if (i.texture > 0.0) {
        let p_W = (u.X_WC * vec4<f32>(i.p_C, 1.0)).xyz;
        c = c * texture_factor(p_W, i.texture);
    }
    var o: FragmentOut;
    o.color = vec4<f32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
    o.depth = i.p_C.z;
    o.object = i.object;
    return o;
}
