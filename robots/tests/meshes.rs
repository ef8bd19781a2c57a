//! Mesh files of every supported format load to the same geometry; scale applies per axis.

use std::path::{Path, PathBuf};

use approx::assert_relative_eq;
use workcell_robots::collision::link_collision_shape;
use workcell_robots::math::Pose;
use workcell_robots::{Coordinate, PackageMap, RobotModel, Shape, TriMesh};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

#[test]
fn unit_cube_in_every_format() {
    for file in [
        "cube_binary.stl",
        "cube_ascii.stl",
        "cube.obj",
        "cube.dae",
        "cube.glb",
    ] {
        let mesh = TriMesh::load(&fixtures().join("meshes").join(file), [1.0, 2.0, 3.0])
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(mesh.triangles.len(), 12, "{file}");
        let (lo, hi) = mesh.bounds();
        for (axis, scale) in [(0, 1.0), (1, 2.0), (2, 3.0)] {
            assert_relative_eq!(lo.to_array()[axis], -0.5 * scale, epsilon = 1e-6);
            assert_relative_eq!(hi.to_array()[axis], 0.5 * scale, epsilon = 1e-6);
        }
        // The convex hull of the scaled cube has volume 1 * 2 * 3.
        let hull = parry3d_f64::shape::SharedShape::convex_hull(&mesh.vertices).expect("hull");
        assert_relative_eq!(hull.mass_properties(1.0).mass(), 6.0, epsilon = 1e-6);
    }
}

#[test]
fn package_uris_relative_paths_and_mimic_joints() {
    let path = fixtures().join("pkg/my_robot/urdf/gripper.urdf");
    let robot = RobotModel::from_urdf_file(&path, &PackageMap::new()).expect("loads");
    assert_eq!(
        robot.dof(),
        3,
        "lift, wrist, left finger; the right finger mimics"
    );
    let right = &robot.joints()[robot.joint_id("finger_right_joint").expect("joint")];
    let left_index =
        match robot.joints()[robot.joint_id("finger_left_joint").expect("joint")].coordinate {
            Coordinate::Own { index } => index,
            other => panic!("left finger should be a coordinate, is {other:?}"),
        };
    assert_eq!(
        right.coordinate,
        Coordinate::Mimic {
            index: left_index,
            multiplier: -1.0,
            offset: 0.0
        }
    );

    // Limits, safety controller, dynamics and acceleration are all read.
    let lift = &robot.joints()[robot.joint_id("lift").expect("joint")];
    assert_eq!(
        (lift.limits.lower, lift.limits.upper, lift.limits.velocity),
        (0.0, 0.5, 0.3)
    );
    assert_eq!(lift.limits.acceleration, 2.0);
    assert_eq!(
        lift.safety_controller
            .expect("safety controller")
            .k_velocity,
        100.0
    );
    let wrist = &robot.joints()[robot.joint_id("wrist").expect("joint")];
    assert!(wrist.limits.lower.is_infinite() && wrist.limits.upper.is_infinite());
    assert_eq!((wrist.damping, wrist.friction), (0.5, 0.1));
    assert_relative_eq!(robot.mass_kg(), 2.0);

    // Meshes: package:// STL scaled for collision, DAE visual with the named material colour.
    let base = &robot.links()[robot.link_id("base").expect("link")];
    match &base.collisions[0].shape {
        Shape::Mesh {
            path, scale, mesh, ..
        } => {
            assert!(path.ends_with(Path::new("my_robot/meshes/cube.stl")));
            assert_eq!(*scale, [0.2, 0.2, 0.1]);
            assert_relative_eq!(mesh.bounds().1.z, 0.05, epsilon = 1e-7);
        }
        other => panic!("expected a mesh, got {other:?}"),
    }
    assert_eq!(base.visuals[0].rgba, Some([0.5, 0.5, 0.5, 1.0]));
    let shape =
        link_collision_shape(&robot, robot.link_id("carriage").expect("link")).expect("shape");
    assert_relative_eq!(
        shape.compute_aabb(&Pose::IDENTITY).maxs.x,
        0.05,
        epsilon = 1e-7
    );

    // Mimic in FK: opening the left finger by 3 cm moves the right one 3 cm the other way.
    let state = robot.fk(Pose::IDENTITY, &[0.0, 0.0, 0.03]).expect("fk");
    let palm = state.link_pose(robot.link_id("palm").expect("link"));
    let fl = palm.inverse() * *state.link_pose(robot.link_id("finger_left").expect("link"));
    let fr = palm.inverse() * *state.link_pose(robot.link_id("finger_right").expect("link"));
    assert_relative_eq!(fl.translation.y, 0.05, epsilon = 1e-12);
    assert_relative_eq!(fr.translation.y, -0.05, epsilon = 1e-12);
}

#[test]
fn truncated_and_corrupted_meshes_are_errors_not_panics() {
    // Every prefix of each fixture, and each fixture with one byte flipped at a time, must
    // give Ok or Err: a broken mesh in a vendor package must never crash a safety tool.
    for file in [
        "cube_binary.stl",
        "cube_ascii.stl",
        "cube.obj",
        "cube.dae",
        "cube.glb",
    ] {
        let path = fixtures().join("meshes").join(file);
        let bytes = std::fs::read(&path).expect("fixture");
        for len in 0..bytes.len() {
            let _ = TriMesh::from_bytes(&bytes[..len], &path, [1.0; 3]);
        }
        for i in 0..bytes.len() {
            let mut flipped = bytes.clone();
            flipped[i] ^= 0x5a;
            let _ = TriMesh::from_bytes(&flipped, &path, [1.0; 3]);
        }
    }
}

#[test]
fn lying_counts_and_odd_names_are_told_apart() {
    let meshes = fixtures().join("meshes");
    let dae = std::fs::read_to_string(meshes.join("cube.dae")).expect("fixture");
    // A count the file cannot hold is refused before the decoder allocates for it (4e9
    // triangles made it ask for 51 GB).
    for (honest, lie) in [
        (
            "<triangles count=\"12\">",
            "<triangles count=\"4294967295\">",
        ),
        ("count=\"24\">", "count=\"4000000000\">"),
        (
            "count=\"8\" stride=\"3\"",
            "count=\"8\" stride=\"4294967295\"",
        ),
    ] {
        assert!(dae.contains(honest), "{honest}");
        let text = dae.replace(honest, lie);
        let err = TriMesh::from_bytes(text.as_bytes(), Path::new("cube.dae"), [1.0; 3])
            .expect_err("lying count");
        assert!(
            err.to_string().contains("claims more values than the"),
            "{lie}: {err}"
        );
    }
    // An ASCII STL whose name is not ASCII is decoded as ASCII, not called a truncated
    // binary file.
    let stl = std::fs::read_to_string(meshes.join("cube_ascii.stl")).expect("fixture");
    let named = stl.replacen("solid cube", "solid würfel", 1);
    let mesh = TriMesh::from_bytes(named.as_bytes(), Path::new("würfel.stl"), [1.0; 3])
        .expect("ASCII STL with a UTF-8 name");
    assert_eq!(mesh.triangles.len(), 12);
}

#[test]
fn deeply_nested_collada_is_an_error_not_a_stack_overflow() {
    let dae = format!(
        "<COLLADA>{}{}</COLLADA>",
        "<node>".repeat(20_000),
        "</node>".repeat(20_000)
    );
    let err =
        TriMesh::from_bytes(dae.as_bytes(), Path::new("deep.dae"), [1.0; 3]).expect_err("too deep");
    assert!(err.to_string().contains("deeper than 256 levels"), "{err}");
}

/// `cube.glb` is the project's own writer's output for `cube.obj` (rewrite it with
/// `WORKCELL_WRITE_FIXTURES=1 cargo test -p workcell-robots --test meshes`). Every format
/// round-trips through glTF to the same triangles, vertices rounded to f32.
#[test]
fn meshes_written_as_glb_load_back() {
    let meshes = fixtures().join("meshes");
    let cube = TriMesh::load(&meshes.join("cube.obj"), [1.0; 3]).expect("cube");
    let glb = cube.to_glb("cube");
    if std::env::var_os("WORKCELL_WRITE_FIXTURES").is_some() {
        std::fs::write(meshes.join("cube.glb"), &glb).expect("write the fixture");
    }
    assert_eq!(
        std::fs::read(meshes.join("cube.glb")).expect("fixture"),
        glb,
        "the writer's output changed: rewrite the fixture if that is intended"
    );
    for file in ["cube_binary.stl", "cube.dae", "cube.obj"] {
        let mesh = TriMesh::load(&meshes.join(file), [1.0; 3]).expect(file);
        let back = TriMesh::from_bytes(&mesh.to_glb(file), Path::new("x.glb"), [1.0; 3])
            .expect("glb back");
        assert_eq!(back.triangles, mesh.triangles, "{file}");
        for (a, b) in back.vertices.iter().zip(&mesh.vertices) {
            assert!((*a - *b).abs().max_element() <= 1e-7 * b.abs().max_element().max(1.0));
        }
    }
}

/// A `.gltf` with its buffer in a data URI and a mesh two nodes deep: the vertices are placed
/// by the product of the nodes' transforms (translation, rotation, scale, and a matrix),
/// and a triangle strip becomes its triangles.
#[test]
fn gltf_scene_graph_places_the_mesh() {
    use base64::Engine as _;
    // A unit square in the x-y plane as a strip of 4 vertices: (0,0), (1,0), (0,1), (1,1).
    let positions: [f32; 12] = [0., 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.];
    let indices: [u32; 4] = [0, 1, 2, 3];
    let mut bin: Vec<u8> = positions.iter().flat_map(|x| x.to_le_bytes()).collect();
    bin.extend(indices.iter().flat_map(|x| x.to_le_bytes()));
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    // Parent: translate (1, 2, 3), scale 2. Child: a quarter turn about z (quaternion
    // (0, 0, sin 45, cos 45)) as TRS, the grandchild a matrix translating by (0, 0, 1).
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"translation": [1.0, 2.0, 3.0], "scale": [2.0, 2.0, 2.0], "children": [1]},
            {"rotation": [0.0, 0.0, h, h], "children": [2]},
            {"matrix": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0], "mesh": 0}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 5}]}],
        "buffers": [{"byteLength": bin.len(), "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 16}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5125, "count": 4, "type": "SCALAR"}
        ]
    });
    let text = doc.to_string();
    let mesh =
        TriMesh::from_bytes(text.as_bytes(), Path::new("square.gltf"), [1.0; 3]).expect("gltf");
    assert_eq!(mesh.triangles.len(), 2, "a strip of 4 is 2 triangles");
    // World = T(1,2,3) S(2) Rz(90) T(0,0,1) p: (x, y, 0) goes to (1 - 2y, 2 + 2x, 5).
    for (v, p) in mesh.vertices.iter().zip(positions.chunks_exact(3)) {
        let (x, y) = (f64::from(p[0]), f64::from(p[1]));
        assert_relative_eq!(v.x, 1.0 - 2.0 * y, epsilon = 1e-6);
        assert_relative_eq!(v.y, 2.0 + 2.0 * x, epsilon = 1e-6);
        assert_relative_eq!(v.z, 5.0, epsilon = 1e-6);
    }
    // Both triangles face the same way (the strip's second one is turned round).
    let normal = |t: [u32; 3]| {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        (b - a).cross(c - a).z
    };
    assert!(normal(mesh.triangles[0]) * normal(mesh.triangles[1]) > 0.0);

    // Broken files: errors that say why, never panics.
    let broken = |doc: serde_json::Value, expected: &str| {
        let err = TriMesh::from_bytes(doc.to_string().as_bytes(), Path::new("b.gltf"), [1.0; 3])
            .expect_err(expected);
        assert!(err.to_string().contains(expected), "{expected}: {err}");
    };
    let mut short = doc.clone();
    short["buffers"][0]["byteLength"] = serde_json::json!(bin.len() + 4);
    broken(short, "declares");
    let mut past = doc.clone();
    past["accessors"][0]["count"] = serde_json::json!(3);
    past["bufferViews"][0]["byteLength"] = serde_json::json!(36);
    broken(past, "past the primitive's 3 vertices");
    let mut looped = doc.clone();
    looped["nodes"][2]["children"] = serde_json::json!([0]);
    broken(looped, "cannot decode");
    let mut missing = doc;
    missing["buffers"][0]["uri"] = serde_json::json!("nowhere.bin");
    broken(missing, "nowhere.bin");
}

/// A URDF whose link is a `.gltf` with its buffer in a file of its own loads, and adding it
/// to a robot library copies the buffer beside the `.gltf`: the added robot loads too.
#[test]
fn gltf_with_an_external_buffer_loads_and_travels_with_its_robot() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cube = TriMesh::load(&fixtures().join("meshes/cube.obj"), [1.0; 3]).expect("cube");
    // Split the project's .glb into a .gltf and a .bin.
    let glb = cube.to_glb("cube");
    let json_len = u32::from_le_bytes([glb[12], glb[13], glb[14], glb[15]]) as usize;
    let mut doc: serde_json::Value =
        serde_json::from_slice(&glb[20..20 + json_len]).expect("json chunk");
    let bin = &glb[20 + json_len + 8..];
    doc["buffers"][0]["uri"] = serde_json::json!("cube_data.bin");
    let meshes = dir.path().join("src/meshes");
    std::fs::create_dir_all(&meshes).expect("mkdir");
    std::fs::write(meshes.join("cube.gltf"), doc.to_string()).expect("gltf");
    std::fs::write(meshes.join("cube_data.bin"), bin).expect("bin");
    let urdf = dir.path().join("src/box.urdf");
    std::fs::write(
        &urdf,
        r#"<robot name="box"><link name="base"><visual><geometry><mesh filename="meshes/cube.gltf"/></geometry></visual><collision><geometry><mesh filename="meshes/cube.gltf"/></geometry></collision></link></robot>"#,
    )
    .expect("urdf");
    let loaded = TriMesh::load(&meshes.join("cube.gltf"), [1.0; 3]).expect("gltf + bin");
    assert_eq!(loaded.triangles, cube.triangles);
    RobotModel::from_urdf_file(&urdf, &PackageMap::new()).expect("robot with a gltf mesh");
    let library = dir.path().join("library");
    let added =
        workcell_robots::assets::add_robot(&urdf, &PackageMap::new(), "box", &library, false)
            .expect("add");
    RobotModel::from_urdf_file(&added.urdf, &PackageMap::new()).expect("the added robot loads");
}

/// A `.gltf` holding one triangle whose buffer is the file `uri`: positions of three
/// vertices, then three `u32` indices.
fn one_triangle_gltf(uri: &str, byte_length: usize) -> String {
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": byte_length, "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}
        ]
    })
    .to_string()
}

/// One triangle's buffer: its positions, then `indices`.
fn triangle_buffer(indices: [u32; 3]) -> Vec<u8> {
    let positions: [f32; 9] = [0., 0., 0., 1., 0., 0., 0., 1., 0.];
    let mut bin: Vec<u8> = positions.iter().flat_map(|x| x.to_le_bytes()).collect();
    bin.extend(indices.iter().flat_map(|x| x.to_le_bytes()));
    bin
}

/// Buffers follow the meshes' rule: a file inside the `.gltf`'s folder (itself inside the
/// package root), never an absolute path, a `..`, a URI scheme or a link out of the folder.
/// `/etc/passwd` as a buffer was read before, and an index error echoed four of its bytes.
#[test]
fn gltf_buffers_stay_inside_the_gltf_folder() {
    let dir = tempfile::tempdir().expect("tempdir");
    let meshes = dir.path().join("pkg/meshes");
    std::fs::create_dir_all(meshes.join("sub")).expect("mkdir");
    // A secret outside the package, shaped as a buffer whose indices spell "SECR".
    let mut secret = triangle_buffer([0, 1, 2]);
    secret.truncate(36);
    secret.extend_from_slice(b"SECRSECRSECR");
    let secret_path = dir.path().join("secret.bin");
    std::fs::write(&secret_path, &secret).expect("secret");
    let secret_index = u32::from_le_bytes(*b"SECR").to_string();
    let load = |uri: &str| {
        let gltf = meshes.join("a.gltf");
        std::fs::write(&gltf, one_triangle_gltf(uri, 48)).expect("gltf");
        TriMesh::load(&gltf, [1.0; 3])
    };
    let absolute = secret_path.to_str().expect("utf-8").to_string();
    let file_uri = format!("file://{absolute}");
    for uri in [
        absolute.as_str(),
        "../../secret.bin",
        "sub/../../../secret.bin",
        "/etc/passwd",
        "../../../../../../../../etc/passwd",
        file_uri.as_str(),
        "http://example.invalid/b.bin",
        "",
    ] {
        let err = load(uri).expect_err(uri);
        assert!(err.to_string().contains("buffer"), "{uri}: {err}");
        assert!(!err.to_string().contains(&secret_index), "{uri}: {err}");
    }
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&secret_path, meshes.join("link.bin")).expect("symlink");
        let err = load("link.bin").expect_err("a link out of the folder");
        assert!(err.to_string().contains("resolves outside"), "{err}");
    }
    // A FIFO beside the .gltf is refused before it is opened (a read would block).
    #[cfg(unix)]
    {
        let fifo = meshes.join("fifo.bin");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let err = load("fifo.bin").expect_err("a FIFO");
            assert!(err.to_string().contains("not a regular file"), "{err}");
        }
    }
    // Inside the folder, in a subfolder too, it loads.
    std::fs::write(meshes.join("sub/ok.bin"), triangle_buffer([0, 1, 2])).expect("bin");
    let mesh = load("sub/ok.bin").expect("a buffer in a subfolder");
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    // An index past the vertices names its position, not its value (the file's bytes).
    std::fs::write(meshes.join("sub/bad.bin"), &secret).expect("bin");
    let err = load("sub/bad.bin").expect_err("indices past the vertices");
    assert!(
        err.to_string().contains("index number 0 points past"),
        "{err}"
    );
    assert!(!err.to_string().contains(&secret_index), "{err}");
}

/// glTF nodes form trees. A 2.5 kB file whose nodes each list the next two as children has
/// 2^63 paths from its root: walked once per path it allocated 6 GB and aborted. A node
/// reached twice (two parents, listed twice in the scene, or a loop) is refused at once.
#[test]
fn gltf_nodes_shared_by_two_parents_are_refused() {
    use base64::Engine as _;
    let bin = triangle_buffer([0, 1, 2]);
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    let mut doc: serde_json::Value =
        serde_json::from_str(&one_triangle_gltf(&uri, 48)).expect("json");
    let n = 64;
    let nodes: Vec<serde_json::Value> = (0..n)
        .map(|k| {
            let children: Vec<usize> = [k + 1, k + 2].into_iter().filter(|&c| c < n).collect();
            if children.is_empty() {
                serde_json::json!({"mesh": 0})
            } else {
                serde_json::json!({"mesh": 0, "children": children})
            }
        })
        .collect();
    doc["nodes"] = serde_json::Value::Array(nodes);
    let text = doc.to_string();
    assert!(text.len() < 4096, "a small file: {} bytes", text.len());
    // Each node is visited at most once, so the refusal comes after at most 64 visits.
    let err = TriMesh::from_bytes(text.as_bytes(), Path::new("dag.gltf"), [1.0; 3])
        .expect_err("a node with two parents");
    assert!(err.to_string().contains("reached twice"), "{err}");
    // The same node twice among the scene's roots.
    doc["nodes"] = serde_json::json!([{"mesh": 0}]);
    doc["scenes"] = serde_json::json!([{"nodes": [0, 0]}]);
    let err = TriMesh::from_bytes(
        doc.to_string().as_bytes(),
        Path::new("twice.gltf"),
        [1.0; 3],
    )
    .expect_err("a root listed twice");
    assert!(err.to_string().contains("reached twice"), "{err}");
    // A tree of the same nodes loads: each node once, each with its own triangle.
    doc["scenes"] = serde_json::json!([{"nodes": [0]}]);
    doc["nodes"] = serde_json::json!([{"mesh": 0, "children": [1, 2]}, {"mesh": 0}, {"mesh": 0}]);
    let mesh = TriMesh::from_bytes(doc.to_string().as_bytes(), Path::new("tree.gltf"), [1.0; 3])
        .expect("a tree");
    assert_eq!(mesh.triangles.len(), 3);
}

/// The kind of a mesh error says what to fix: the file (unreadable), its bytes (not a mesh),
/// or a file it names (out of reach).
#[test]
fn mesh_errors_say_which_kind_of_problem() {
    use workcell_robots::{MeshError, gltf_buffer_path};
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("missing.stl");
    assert!(matches!(
        TriMesh::load(&missing, [1.0; 3]),
        Err(MeshError::Read(m)) if m.contains("missing.stl")
    ));
    assert!(matches!(
        TriMesh::from_bytes(b"solid nothing", Path::new("x.stl"), [1.0; 3]),
        Err(MeshError::Decode(_))
    ));
    let gltf = dir.path().join("a.gltf");
    assert!(matches!(
        gltf_buffer_path(&gltf, "../secret.bin"),
        Err(MeshError::Refused(m)) if m.contains("../secret.bin")
    ));
    assert_eq!(
        gltf_buffer_path(&gltf, "sub/a.bin").expect("inside"),
        dir.path().join("sub/a.bin")
    );
}
