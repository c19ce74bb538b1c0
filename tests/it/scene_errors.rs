//! Every bad input is an error naming the file, the line (and column where known) and the
//! problem; none panics.

use stagelight::scene::{self, SceneError};
use std::path::PathBuf;

const CAMERA: &str = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40),";
const MATERIAL: &str = "\"spare\": Diffuse(reflectance: (0.2, 0.2, 0.2)),";
const OBJECT: &str = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\"),";

/// A scene whose camera is on line 2, whose second material is on line 5 and whose second
/// object is on line 9 (column 5).
fn scene(camera: &str, material: &str, object: &str) -> String {
    format!(
        "Scene(
  {camera}
  materials: {{
    \"m\": Diffuse(reflectance: (0.5, 0.5, 0.5)),
    {material}
  }},
  objects: [
    (shape: Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), material: \"m\"),
    {object}
  ],
)
"
    )
}

fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "stagelight_scene_errors_{test}_{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Loads `text` from a file named after the test and returns the error's Display.
fn load_error(test: &str, text: &str) -> (SceneError, String) {
    let scratch = temp_dir(test);
    let path = scratch.join(format!("{test}.ron"));
    std::fs::write(&path, text).unwrap();
    match scene::load(&path) {
        Ok(_) => panic!("{test}: loaded without error:\n{text}"),
        Err(e) => {
            let shown = e.to_string();
            assert!(
                shown.contains(&format!("{test}.ron")),
                "{test}: no file name in: {shown}"
            );
            (e, shown)
        }
    }
}

/// Asserts the error is at `line` (and `column` when given) and mentions every phrase.
fn expect(test: &str, text: &str, line: usize, column: Option<usize>, phrases: &[&str]) {
    let (e, shown) = load_error(test, text);
    assert_eq!(e.line, Some(line), "{test}: wrong line in: {shown}");
    assert!(shown.contains(&format!(".ron:{line}:")), "{test}: {shown}");
    if let Some(column) = column {
        assert_eq!(e.column, Some(column), "{test}: wrong column in: {shown}");
        assert!(
            shown.contains(&format!(":{line}:{column}:")),
            "{test}: {shown}"
        );
    }
    for phrase in phrases {
        assert!(
            shown.to_lowercase().contains(&phrase.to_lowercase()),
            "{test}: \"{phrase}\" missing from: {shown}"
        );
    }
}

fn loads(test: &str, text: &str) {
    let scratch = temp_dir(test);
    let path = scratch.join(format!("{test}.ron"));
    std::fs::write(&path, text).unwrap();
    if let Err(e) = scene::load(&path) {
        panic!("{test}: {e}");
    }
}

#[test]
fn the_template_itself_loads() {
    loads("template", &scene(CAMERA, MATERIAL, OBJECT));
}

#[test]
fn malformed_ron() {
    // A missing comma between two fields of the object on line 9.
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)) material: \"spare\"),";
    expect(
        "malformed",
        &scene(CAMERA, MATERIAL, object),
        9,
        None,
        &["comma"],
    );
    // Unbalanced parentheses: the file ends early.
    let text = scene(CAMERA, MATERIAL, OBJECT);
    let truncated = &text[..text.rfind(')').unwrap()];
    let (e, shown) = load_error("truncated", truncated);
    assert!(e.line.is_some(), "{shown}");
}

#[test]
fn missing_scene_file() {
    let scratch = temp_dir("missing");
    let path = scratch.join("no_such_scene.ron");
    let e = scene::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("no_such_scene.ron") && e.contains("cannot read"),
        "{e}"
    );
}

#[test]
fn unknown_fields() {
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40, aperture: 2),";
    expect(
        "unknown_camera_field",
        &scene(camera, MATERIAL, OBJECT),
        2,
        None,
        &["aperture"],
    );
    let object =
        "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\", colour: 3),";
    expect(
        "unknown_object_field",
        &scene(CAMERA, MATERIAL, object),
        9,
        None,
        &["field", "colour"],
    );
    let material = "\"spare\": Diffuse(reflectance: (0.2, 0.2, 0.2), sheen: 1),";
    expect(
        "unknown_material_field",
        &scene(CAMERA, material, OBJECT),
        5,
        None,
        &["field", "sheen"],
    );
    let text = scene(CAMERA, MATERIAL, OBJECT).replace("  objects:", "  lights: [],\n  objects:");
    expect("unknown_scene_field", &text, 7, None, &["field", "lights"]);
}

#[test]
fn unknown_material_name() {
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"gold\"),";
    expect(
        "unknown_material",
        &scene(CAMERA, MATERIAL, object),
        9,
        Some(5),
        &["unknown material", "gold"],
    );
}

#[test]
fn unknown_variants() {
    let object = "(shape: Cylinder(radius: 1), material: \"spare\"),";
    expect(
        "unknown_shape",
        &scene(CAMERA, MATERIAL, object),
        9,
        None,
        &["variant", "Cylinder"],
    );
    let material = "\"spare\": Velvet(reflectance: (0.2, 0.2, 0.2)),";
    expect(
        "unknown_material_kind",
        &scene(CAMERA, material, OBJECT),
        5,
        None,
        &["variant", "Velvet"],
    );
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\", transform: [Shear(1)]),";
    expect(
        "unknown_transform",
        &scene(CAMERA, MATERIAL, object),
        9,
        None,
        &["variant", "Shear"],
    );
}

#[test]
fn missing_or_malformed_ply_file() {
    let object = "(shape: Ply(\"meshes/absent.ply\"), material: \"spare\"),";
    expect(
        "missing_ply",
        &scene(CAMERA, MATERIAL, object),
        9,
        Some(5),
        &["meshes/absent.ply", "cannot read"],
    );
    let dir = temp_dir("malformed_ply");
    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                  property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                  end_header\n";
    for (file, body, phrase) in [
        ("truncated.ply", "0 0 0\n1 0 0\n", "end of file"),
        (
            "dangling.ply",
            "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
            "refers to vertex 7",
        ),
        (
            "word.ply",
            "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n",
            "element \"vertex\"",
        ),
    ] {
        std::fs::write(dir.join(file), format!("{header}{body}")).unwrap();
        let object = format!("(shape: Ply(\"{file}\"), material: \"spare\"),");
        expect(
            "malformed_ply",
            &scene(CAMERA, MATERIAL, &object),
            9,
            Some(5),
            &[file, phrase],
        );
    }
    // The same file, whole, loads.
    std::fs::write(
        dir.join("whole.ply"),
        format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    )
    .unwrap();
    let path = dir.join("whole.ron");
    let object = "(shape: Ply(\"whole.ply\"), material: \"spare\"),";
    std::fs::write(&path, scene(CAMERA, MATERIAL, object)).unwrap();
    scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn missing_mesh_file() {
    let object = "(shape: Obj(\"meshes/absent.obj\"), material: \"spare\"),";
    expect(
        "missing_mesh",
        &scene(CAMERA, MATERIAL, object),
        9,
        Some(5),
        &["meshes/absent.obj", "cannot read"],
    );
}

#[test]
fn malformed_mesh_file() {
    let dir = temp_dir("malformed_mesh");
    std::fs::write(dir.join("broken.obj"), "v 0 0 0\nv 1 0 zero\nf 1 2 3\n").unwrap();
    let object = "(shape: Obj(\"broken.obj\"), material: \"spare\"),";
    expect(
        "malformed_mesh",
        &scene(CAMERA, MATERIAL, object),
        9,
        Some(5),
        &["broken.obj", "malformed"],
    );
    // A face that refers to a vertex the file does not have.
    std::fs::write(dir.join("dangling.obj"), "v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap();
    let object = "(shape: Obj(\"dangling.obj\"), material: \"spare\"),";
    let text = scene(CAMERA, MATERIAL, object);
    let path = dir.join("malformed_mesh.ron");
    std::fs::write(&path, text).unwrap();
    let e = scene::load(&path).unwrap_err();
    assert_eq!(e.line, Some(9));
    assert!(e.to_string().contains("dangling.obj"), "{e}");
}

#[test]
fn negative_radiance() {
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\",\n     emission: Some((1, -2, 1))),";
    // The emission is on the object's second line.
    expect(
        "negative_radiance",
        &scene(CAMERA, MATERIAL, object),
        10,
        None,
        &["radiance", "non-negative"],
    );
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\", emission: Some((0, 0, 0))),";
    expect(
        "zero_radiance",
        &scene(CAMERA, MATERIAL, object),
        9,
        None,
        &["radiance", "zero"],
    );
}

#[test]
fn reflectance_out_of_range() {
    let material = "\"spare\": Diffuse(reflectance: (0.2, -0.1, 0.2)),";
    expect(
        "negative_reflectance",
        &scene(CAMERA, material, OBJECT),
        5,
        None,
        &["reflectance", "[0, 1]"],
    );
    let material = "\"spare\": Conductor(alpha: 0.5, reflectance: (1.2, 0.5, 0.5)),";
    expect(
        "reflectance_above_one",
        &scene(CAMERA, material, OBJECT),
        5,
        None,
        &["reflectance", "[0, 1]"],
    );
}

#[test]
fn fov_out_of_range() {
    for (name, fov) in [
        ("fov_zero", "0"),
        ("fov_180", "180"),
        ("fov_negative", "-10"),
        ("fov_huge", "200.5"),
    ] {
        let camera = format!("camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: {fov}),");
        expect(
            name,
            &scene(&camera, MATERIAL, OBJECT),
            2,
            None,
            &["fov", "(0, 180)"],
        );
    }
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 179.9),";
    loads("fov_179", &scene(camera, MATERIAL, OBJECT));
}

#[test]
fn bad_ior() {
    for (name, ior) in [
        ("ior_zero", "0"),
        ("ior_negative", "-1.5"),
        ("ior_nan", "NaN"),
        ("ior_inf", "inf"),
    ] {
        let material = format!("\"spare\": Dielectric(ior: {ior}),");
        expect(
            name,
            &scene(CAMERA, &material, OBJECT),
            5,
            None,
            &["ior", "positive"],
        );
    }
}

#[test]
fn ggx_alpha_range() {
    for (name, alpha) in [
        ("alpha_zero", "0"),
        ("alpha_negative", "-0.1"),
        ("alpha_above_one", "1.01"),
        ("alpha_nan", "NaN"),
    ] {
        let material =
            format!("\"spare\": Conductor(alpha: {alpha}, reflectance: (0.9, 0.9, 0.9)),");
        expect(
            name,
            &scene(CAMERA, &material, OBJECT),
            5,
            None,
            &["alpha", "(0, 1]"],
        );
    }
    for (name, alpha) in [("alpha_tiny", "1e-4"), ("alpha_one", "1.0")] {
        let material =
            format!("\"spare\": Conductor(alpha: {alpha}, reflectance: (0.9, 0.9, 0.9)),");
        loads(name, &scene(CAMERA, &material, OBJECT));
    }
}

#[test]
fn degenerate_light() {
    // All four corners on one line: every triangle has zero area.
    let object = "(name: Some(\"lamp\"), shape: Quad((0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)), material: \"spare\", emission: Some((5, 5, 5))),";
    expect(
        "degenerate_light",
        &scene(CAMERA, MATERIAL, object),
        9,
        Some(5),
        &["degenerate light", "zero total area", "lamp"],
    );
}

#[test]
fn bad_camera() {
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 3, -5), fov: 40),";
    expect(
        "camera_along_up",
        &scene(camera, MATERIAL, OBJECT),
        2,
        Some(11),
        &["up", "parallel"],
    );
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), up: (0, 0, -2), fov: 40),";
    expect(
        "camera_along_down",
        &scene(camera, MATERIAL, OBJECT),
        2,
        Some(11),
        &["up", "parallel"],
    );
    let camera = "camera: (position: (1, 2, 3), look_at: (1, 2, 3), fov: 40),";
    expect(
        "camera_no_direction",
        &scene(camera, MATERIAL, OBJECT),
        2,
        Some(11),
        &["look_at", "same point"],
    );
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), up: (0, 0, 0), fov: 40),";
    expect(
        "camera_zero_up",
        &scene(camera, MATERIAL, OBJECT),
        2,
        Some(11),
        &["up", "zero"],
    );
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0)),";
    expect(
        "camera_no_fov",
        &scene(camera, MATERIAL, OBJECT),
        2,
        None,
        &["fov"],
    );
}

#[test]
fn image_size_zero() {
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40, width: 0),";
    expect(
        "width_zero",
        &scene(camera, MATERIAL, OBJECT),
        2,
        None,
        &["image size", "1..="],
    );
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40, height: 0),";
    expect(
        "height_zero",
        &scene(camera, MATERIAL, OBJECT),
        2,
        None,
        &["image size", "1..="],
    );
    let camera = "camera: (position: (0, 0, -5), look_at: (0, 0, 0), fov: 40, height: -3),";
    load_error("height_negative", &scene(camera, MATERIAL, OBJECT));
}

#[test]
fn shape_parameters_out_of_range() {
    let cases = [
        (
            "torus_nu_2",
            "Torus(major_radius: 1, minor_radius: 0.2, nu: 2, nv: 8)",
            "segment count",
        ),
        (
            "torus_nv_0",
            "Torus(major_radius: 1, minor_radius: 0.2, nu: 8, nv: 0)",
            "segment count",
        ),
        (
            "torus_r_zero",
            "Torus(major_radius: 1, minor_radius: 0, nu: 8, nv: 8)",
            "radius",
        ),
        (
            "torus_r_negative",
            "Torus(major_radius: -1, minor_radius: 0.2, nu: 8, nv: 8)",
            "radius",
        ),
        ("ico_level_9", "Icosphere(level: 9)", "level"),
        ("ico_level_negative", "Icosphere(level: -1)", "level"),
        (
            "box_inverted",
            "Box(min: (0, 0, 0), max: (1, -1, 1))",
            "below max",
        ),
    ];
    for (name, shape, phrase) in cases {
        let object = format!("(shape: {shape}, material: \"spare\"),");
        expect(name, &scene(CAMERA, MATERIAL, &object), 9, None, &[phrase]);
    }
}

#[test]
fn bad_transforms() {
    let cases = [
        ("scale_zero", "[Scale(0)]", "scale"),
        ("scale_axis_zero", "[Scale((1, 0, 1))]", "scale"),
        (
            "rotate_zero_axis",
            "[Rotate(axis: (0, 0, 0), degrees: 10)]",
            "axis",
        ),
        ("translate_nan", "[Translate((0, NaN, 0))]", "finite"),
    ];
    for (name, transform, phrase) in cases {
        let object = format!(
            "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"spare\", transform: {transform}),"
        );
        expect(name, &scene(CAMERA, MATERIAL, &object), 9, None, &[phrase]);
    }
}

#[test]
fn duplicate_material() {
    let material = "\"m\": Diffuse(reflectance: (0.2, 0.2, 0.2)),";
    expect(
        "duplicate_material",
        &scene(CAMERA, material, OBJECT),
        5,
        None,
        &["defined twice"],
    );
}

#[test]
fn scene_without_triangles() {
    let text = format!("Scene({CAMERA} materials: {{}}, objects: [])");
    let (_, shown) = load_error("empty", &text);
    assert!(shown.contains("no triangles"), "{shown}");
}

#[test]
fn garbage_never_panics() {
    // Truncations of a valid scene at every position are errors, never panics.
    let text = scene(CAMERA, MATERIAL, OBJECT);
    let dir = temp_dir("garbage");
    for end in (0..text.len()).step_by(7) {
        let path = dir.join("garbage.ron");
        std::fs::write(&path, &text[..end]).unwrap();
        assert!(scene::load(&path).is_err(), "prefix of {end} bytes loaded");
    }
}

#[test]
fn object_position_skips_leading_comments() {
    // The object starts on line 10, after a comment line.
    let object = "// a lamp\n    (shape: Triangle((0, 0, 0), (1, 0, 0), (2, 0, 0)), material: \"spare\", emission: Some((1, 1, 1))),";
    expect(
        "comment_before_object",
        &scene(CAMERA, MATERIAL, object),
        10,
        Some(5),
        &["degenerate light"],
    );
}
