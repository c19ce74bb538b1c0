//! "prepare": reads the scene world once into the flat columns the renderer uses.

use super::lights::{PointProfile, Spot};
use super::world::{
    DeclaredIn, Emission, FlipNormals, MaterialInfo, MaterialRef, ObjectInfo, SceneWorld, Shape,
    SourceSpot, Transform,
};
use super::{Camera, Emitters, FLAT, NO_EMITTER, PreparedScene, SceneError, TriangleColumns};
use crate::bsdf::Material;
use crate::math::luminance;
use glam::{DVec3, Vec3};
use hecs::Entity;
use std::collections::{HashMap, HashSet};
use std::f64::consts::PI;

/// A triangle whose doubled area is below this fraction of its longest squared edge is
/// degenerate in f32 (its normal is rounding noise) and is dropped.
const MIN_RELATIVE_AREA: f64 = 1e-6;

pub fn prepare(scene: &SceneWorld) -> Result<PreparedScene, SceneError> {
    let world = &scene.world;
    let error = |spot: Option<(&SourceSpot, Option<&DeclaredIn>)>, message: String| SceneError {
        file: spot
            .and_then(|(_, file)| file)
            .map_or_else(|| scene.source.clone(), |f| f.0.clone()),
        line: spot.map(|s| s.0.line),
        column: spot.map(|s| s.0.column),
        message,
    };

    let camera = {
        let mut query = world.query::<&Camera>();
        let cameras: Vec<Camera> = query.iter().copied().collect();
        match cameras[..] {
            [camera] => camera,
            _ => return Err(error(None, "a scene needs exactly one camera".to_string())),
        }
    };

    let mut object_query = world.query::<(
        &ObjectInfo,
        &SourceSpot,
        &Shape,
        &Transform,
        &MaterialRef,
        Option<&Emission>,
        Option<&FlipNormals>,
        Option<&DeclaredIn>,
    )>();
    let mut objects: Vec<_> = object_query.iter().collect();
    // Triangle ids follow the file, whatever order hecs stores archetypes in.
    objects.sort_by_key(|o| o.0.order);

    // Only the materials some object uses, in declaration order.
    let mut material_query = world.query::<(
        Entity,
        &MaterialInfo,
        &Material,
        Option<&super::world::OneSided>,
        Option<&super::world::SurfaceVarying>,
        Option<&super::world::BackMaterial>,
    )>();
    let mut declared: Vec<_> = material_query.iter().collect();
    declared.sort_by_key(|m| m.1.order);
    let mut used: HashSet<Entity> = objects.iter().map(|o| o.4.0).collect();
    // A used twosided's back material is used too.
    for &(entity, _, _, _, _, back) in &declared {
        if let (true, Some(back)) = (used.contains(&entity), back) {
            used.insert(back.0);
        }
    }
    let mut materials = Vec::new();
    let mut black_behind = Vec::new();
    let mut varying = Vec::new();
    let mut textures = Vec::new();
    let mut material_index = HashMap::new(); // entity -> index into `materials`
    let mut warnings = scene.warnings.clone();
    for &(entity, info, material, one_sided, varies, _) in &declared {
        if used.contains(&entity) {
            varying.push(varies.and_then(|v| {
                let mut add = |t: &Option<super::textures::Texture>| {
                    t.as_ref().map(|t| {
                        textures.push(t.clone());
                        textures.len() as u32 - 1
                    })
                };
                let reflectance = add(&v.reflectance);
                let alpha_u = add(&v.alpha_u);
                // An isotropic alpha's one texture serves both roughnesses.
                let alpha_v = if v.alpha_v.is_some() && v.alpha_v == v.alpha_u {
                    alpha_u
                } else {
                    add(&v.alpha_v)
                };
                // Anisotropic where the two roughnesses can differ: different textures, or one
                // texture and one value, or two different values.
                let roughnesses = match material {
                    Material::Conductor(c) => Some((c.alpha_u, c.alpha_v)),
                    Material::RoughDielectric(d) => Some((d.alpha_u, d.alpha_v)),
                    _ => None,
                };
                let anisotropic = roughnesses.is_some_and(|(u, v_)| {
                    v.anisotropic && (alpha_u != alpha_v || (alpha_u.is_none() && u != v_))
                });
                let varies = reflectance.is_some() || alpha_u.is_some() || anisotropic;
                varies.then_some(super::Varying {
                    reflectance,
                    alpha_u,
                    alpha_v,
                    anisotropic,
                })
            }));
            material_index.insert(entity, materials.len() as u32);
            materials.push(*material);
            // Only a material the engine would mirror to the side a ray comes from needs the
            // mark; the others are black from behind by their own maths.
            black_behind.push(one_sided.is_some() && material.is_two_sided());
        } else {
            warnings.push(format!(
                "material \"{}\" is not used",
                super::echo(&info.name)
            ));
        }
    }
    // Per material, the material seen from behind (a twosided of two BSDFs' back).
    let back: Vec<Option<u32>> = declared
        .iter()
        .filter(|m| material_index.contains_key(&m.0))
        .map(|m| m.5.map(|b| material_index[&b.0]))
        .collect();
    let mut power = DVec3::ZERO;
    let mut triangle_uvs = Vec::new();

    let mut triangles = TriangleColumns::default();
    let mut emitters = Emitters::default();
    for (info, spot, shape, transform, material, emission, flip, declared_in) in objects {
        let spot = (spot, declared_in);
        let describe = || match &info.name {
            Some(name) => format!("object \"{}\" (line {})", super::echo(name), spot.0.line),
            None => format!("object #{} (line {})", info.order + 1, spot.0.line),
        };
        let material = *material_index
            .get(&material.0)
            .ok_or_else(|| error(Some(spot), "object's material entity is missing".into()))?;
        let mesh = &shape.0;
        let affine = transform.0;
        // Normals transform by the inverse transpose; a mirroring transform reverses the
        // winding, so the geometric normal keeps pointing to the same side of the surface.
        let normal_matrix = affine.matrix3.inverse().transpose();
        let mirrored = affine.matrix3.determinant() < 0.0;
        let flip_normals = flip.is_some();
        let reverse = mirrored != flip_normals;

        let positions: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|&p| affine.transform_point3(p).as_vec3())
            .collect();
        if positions.iter().any(|p| !p.is_finite()) {
            return Err(error(
                Some(spot),
                format!("{}: transformed vertices are not finite", describe()),
            ));
        }
        // In f64, before rounding: a vertex beyond f32's range is caught here too.
        if let Some(far) = mesh
            .positions
            .iter()
            .map(|&p| affine.transform_point3(p))
            .find(|p| p.abs().max_element() >= super::MAX_COORDINATE)
        {
            return Err(error(
                Some(spot),
                format!(
                    "{}: vertex {:?} is too far out: coordinates (after the transforms) must \
                     stay below {:e} in magnitude",
                    describe(),
                    far.as_vec3().to_array(),
                    super::MAX_COORDINATE
                ),
            ));
        }
        let normals: Option<Vec<Vec3>> = mesh.normals.as_ref().map(|normals| {
            normals
                .iter()
                .map(|&n| {
                    let n = (normal_matrix * n).try_normalize().unwrap_or(DVec3::ZERO);
                    (if flip_normals { -n } else { n }).as_vec3()
                })
                .collect()
        });

        let mut dropped = 0usize;
        let mut emitting = 0usize;
        for &[a, b, c] in &mesh.triangles {
            let corners = if reverse { [a, c, b] } else { [a, b, c] };
            // Mitsuba's uv where a mesh has none: the barycentric coordinates (b1, b2).
            let uvs = match &mesh.uvs {
                Some(uvs) => corners.map(|i| uvs[i as usize].as_vec2()),
                None if reverse => [glam::Vec2::ZERO, glam::Vec2::Y, glam::Vec2::X],
                None => [glam::Vec2::ZERO, glam::Vec2::X, glam::Vec2::Y],
            };
            let [p0, p1, p2] = corners.map(|i| positions[i as usize]);
            let (e1, e2, e3) = (
                (p1 - p0).as_dvec3(),
                (p2 - p0).as_dvec3(),
                (p2 - p1).as_dvec3(),
            );
            let doubled_area = e1.cross(e2).length();
            let longest = e1
                .length_squared()
                .max(e2.length_squared())
                .max(e3.length_squared());
            // Positions are finite here, so the comparison is never NaN; equal points give 0 <= 0.
            // An emitter's area must also be a normal f32: light sampling divides by it (a
            // light of side 2e-23 has an f32 area of 0).
            let area = (0.5 * doubled_area) as f32;
            if doubled_area <= MIN_RELATIVE_AREA * longest
                || (emission.is_some() && area < f32::MIN_POSITIVE)
            {
                dropped += 1;
                continue;
            }
            if triangles.len() >= super::POINT_LIGHT as usize {
                return Err(error(Some(spot), "too many triangles".to_string()));
            }
            let id = triangles.len() as u32;
            triangles.p0.push(p0);
            triangles.p1.push(p1);
            triangles.p2.push(p2);
            triangles.normal.push(e1.cross(e2).normalize().as_vec3());
            triangles.material.push(material);
            if varying.iter().any(Option::is_some) {
                triangle_uvs.push(uvs);
            }

            let vertex_normals = normals
                .as_ref()
                .map(|n| corners.map(|i| n[i as usize]))
                .filter(|n| n.iter().all(|v| *v != Vec3::ZERO));
            match vertex_normals {
                Some(n) => {
                    triangles.smooth.push(triangles.vertex_normals.len() as u32);
                    triangles.vertex_normals.push(n);
                }
                None => triangles.smooth.push(FLAT),
            }

            match emission {
                Some(Emission(radiance)) => {
                    triangles.emitter.push(emitters.triangle.len() as u32);
                    emitters.triangle.push(id);
                    emitters.radiance.push(*radiance);
                    emitters.area.push(area);
                    emitters.position.push(Vec3::ZERO);
                    emitters.profile.push(PointProfile::Uniform);
                    power += PI * area as f64 * radiance.as_dvec3();
                    emitting += 1;
                }
                None => triangles.emitter.push(NO_EMITTER),
            }
        }
        if dropped > 0 {
            warnings.push(format!(
                "{}: dropped {dropped} zero-area triangle{}",
                describe(),
                if dropped == 1 { "" } else { "s" }
            ));
        }
        if emission.is_some() && emitting == 0 {
            return Err(error(
                Some(spot),
                format!(
                    "{}: degenerate light: the emissive object has zero total area",
                    describe()
                ),
            ));
        }
        if power.max_element() > super::MAX_POWER {
            return Err(error(
                Some(spot),
                format!(
                    "{}: the emitted power (pi x area x radiance, summed over the lights so \
                     far) reaches {:.3e}: it must stay below {:e} (f32 light transport \
                     overflows)",
                    describe(),
                    power.max_element(),
                    super::MAX_POWER
                ),
            ));
        }
    }
    if triangles.is_empty() {
        return Err(error(None, "the scene has no triangles".to_string()));
    }
    let mut point_query = world.query::<(
        &super::world::PointLight,
        &SourceSpot,
        Option<&DeclaredIn>,
        Option<&super::world::ProjectedTexture>,
    )>();
    let mut points: Vec<_> = point_query.iter().collect();
    points.sort_by_key(|p| p.0.order);
    for (light, spot, declared_in, texture) in points {
        let mut light = *light;
        let index = emitters.projected_textures.len() as u32;
        let projects = match &mut light.profile {
            PointProfile::Spot(Spot {
                projection: Some(projection),
                ..
            }) => Some(&mut projection.texture),
            PointProfile::Projector(projector) => Some(&mut projector.texture),
            _ => None,
        };
        if let (Some(texture), Some(slot)) = (texture, projects) {
            *slot = index;
            emitters.projected_textures.push(texture.0.clone());
        }
        let position = light.position.as_vec3();
        if !position.is_finite() || light.position.abs().max_element() >= super::MAX_COORDINATE {
            return Err(error(
                Some((spot, declared_in)),
                "point light: its position is not finite or lies beyond the scene's coordinate range".into(),
            ));
        }
        let e = emitters.triangle.len() as u32;
        emitters.triangle.push(super::POINT_LIGHT | e);
        emitters.radiance.push(light.intensity);
        emitters.area.push(1.0);
        emitters.position.push(position);
        emitters.profile.push(light.profile);
        let solid_angle = light.profile.weighted_solid_angle();
        power += solid_angle * light.intensity.as_dvec3();
        if power.max_element() > super::MAX_POWER {
            return Err(error(
                Some((spot, declared_in)),
                format!(
                    "point light: the emitted power (4 pi x intensity, summed over the lights \
                     so far) reaches {:.3e}: it must stay below {:e}",
                    power.max_element(),
                    super::MAX_POWER
                ),
            ));
        }
    }
    let mut directional_query = world.query::<(
        &super::world::DirectionalLight,
        &SourceSpot,
        Option<&DeclaredIn>,
    )>();
    let mut directionals: Vec<_> = directional_query.iter().collect();
    directionals.sort_by_key(|d| d.0.order);
    let mut environment_query = world.query::<(
        &super::world::EnvironmentLight,
        &SourceSpot,
        Option<&DeclaredIn>,
    )>();
    let environments: Vec<_> = environment_query.iter().collect();
    if let [_, second, ..] = environments.as_slice() {
        return Err(error(
            Some((second.1, second.2)),
            "a scene holds at most one light at infinity (constant or envmap), as in Mitsuba"
                .into(),
        ));
    }
    // Lights at infinity start their light paths on a disk as wide as the scene's bounding
    // sphere, and their power is what they can deliver to the scene: their mean irradiance on
    // a surface (a quarter of the radiance integrated over the sphere; a quarter of a
    // directional light's irradiance, a convex body's mean projected area being a quarter of
    // its area) times the area that receives it: the surfaces' own (one side each) or, where
    // that is more, the bounding sphere's, which all their light into the scene crosses
    // (pbrt-v4's pi r^2 bound). The sphere alone made a flat scene's spot light 20 times
    // rarer than Mitsuba's pick.
    let mut receiving_area = 0.0;
    if !directionals.is_empty() || !environments.is_empty() {
        let (lo, hi) = (
            all_points(&triangles).fold(DVec3::INFINITY, |m, p| m.min(p.as_dvec3())),
            all_points(&triangles).fold(DVec3::NEG_INFINITY, |m, p| m.max(p.as_dvec3())),
        );
        let radius = 0.5 * (hi - lo).length();
        emitters.disk = super::environment::SceneDisk {
            center: (0.5 * (lo + hi)).as_vec3(),
            radius: (radius * (1.0 + 1e-4)).max(1e-4) as f32,
        };
        let surface_area: f64 = (0..triangles.len())
            .map(|i| {
                let (p0, p1, p2) = (
                    triangles.p0[i].as_dvec3(),
                    triangles.p1[i].as_dvec3(),
                    triangles.p2[i].as_dvec3(),
                );
                0.5 * (p1 - p0).cross(p2 - p0).length()
            })
            .sum();
        receiving_area = surface_area.min(4.0 * PI * radius * radius);
    }
    let too_bright = |power: DVec3, spot, declared_in| {
        error(
            Some((spot, declared_in)),
            format!(
                "light at infinity: its power (its mean irradiance times the scene's area, with \
                 the lights before it) reaches {:.3e}: it must stay below {:e}",
                power.max_element(),
                super::MAX_POWER
            ),
        )
    };
    for (light, spot, declared_in) in directionals {
        let direction = light.direction.normalize().as_vec3();
        if !direction.is_finite() {
            return Err(error(
                Some((spot, declared_in)),
                "directional light: its direction is zero or not finite".into(),
            ));
        }
        let e = emitters.triangle.len() as u32;
        emitters
            .triangle
            .push(super::POINT_LIGHT | super::AT_INFINITY | e);
        emitters.radiance.push(light.irradiance);
        emitters.area.push(1.0);
        emitters.position.push(direction);
        emitters.profile.push(PointProfile::Uniform);
        power += 0.25 * receiving_area * light.irradiance.as_dvec3();
        if power.is_nan() || power.max_element() > super::MAX_POWER {
            return Err(too_bright(power, spot, declared_in));
        }
    }
    if let [(light, spot, declared_in)] = environments.as_slice() {
        let env = &light.0;
        power += 0.25 * receiving_area * env.irradiance_over_sphere();
        if power.is_nan() || power.max_element() > super::MAX_POWER {
            return Err(too_bright(power, spot, *declared_in));
        }
        emitters.triangle.push(super::ENVIRONMENT);
        // The brightest radiance it sends (the film's fixed-point unit follows it).
        emitters.radiance.push(env.peak_radiance());
        emitters.area.push(1.0);
        emitters.position.push(Vec3::ZERO);
        emitters.profile.push(PointProfile::Uniform);
        emitters.environment = Some(env.clone());
    }
    drop(environment_query);
    drop(directional_query);
    if emitters.triangle.is_empty() {
        warnings.push("no object emits light: the image will be black".to_string());
    }
    build_distribution(&mut emitters, receiving_area);
    if emitters.cdf.len() != emitters.triangle.len() {
        return Err(error(
            None,
            "the lights' power is not a positive finite number: no light can be sampled".into(),
        ));
    }

    let bounds_min = all_points(&triangles).fold(Vec3::INFINITY, |m, p| m.min(*p));
    let bounds_max = all_points(&triangles).fold(Vec3::NEG_INFINITY, |m, p| m.max(*p));

    let mut prepared = PreparedScene {
        source: scene.source.clone(),
        camera,
        triangles,
        materials,
        black_behind,
        back,
        varying,
        textured: false,
        textures,
        triangle_uvs,
        emitters,
        bounds_min,
        bounds_max,
        warnings,
    };
    prepared.textured = prepared.uses_textures();
    prepared.triangles.move_to_huge_pages();
    Ok(prepared)
}

/// Every triangle corner.
fn all_points(triangles: &TriangleColumns) -> impl Iterator<Item = &Vec3> {
    triangles
        .p0
        .iter()
        .chain(&triangles.p1)
        .chain(&triangles.p2)
}

/// Fills pmf (proportional to pi * area * luminance), cdf (ending at exactly 1) and the total
/// power, summing in double precision.
fn build_distribution(emitters: &mut Emitters, receiving_area: f64) {
    let powers: Vec<DVec3> = emitters
        .radiance
        .iter()
        .zip(&emitters.area)
        .zip(&emitters.triangle)
        .enumerate()
        .map(|(e, ((l, &area), &triangle))| {
            if triangle == super::ENVIRONMENT {
                let env = emitters
                    .environment
                    .as_ref()
                    .expect("the environment's emitter");
                0.25 * receiving_area * env.irradiance_over_sphere()
            } else if super::is_at_infinity(triangle) {
                // A directional light: `l` is its irradiance.
                0.25 * receiving_area * l.as_dvec3()
            } else if triangle & super::POINT_LIGHT != 0 {
                emitters.profile[e].weighted_solid_angle() * l.as_dvec3()
            } else {
                PI * area as f64 * l.as_dvec3()
            }
        })
        .collect();
    let weights: Vec<f64> = powers
        .iter()
        .map(|p| luminance(p.as_vec3()) as f64)
        .collect();
    let total: f64 = weights.iter().sum();
    emitters.total_power = powers.iter().sum::<DVec3>().as_vec3();
    if total <= 0.0 {
        // No emitters (radiance is checked to be non-zero, so luminance is positive).
        return;
    }
    emitters.pmf = weights.iter().map(|w| (w / total) as f32).collect();
    let mut running = 0.0;
    emitters.cdf = weights
        .iter()
        .map(|w| {
            running += w;
            (running / total) as f32
        })
        .collect();
    if let Some(last) = emitters.cdf.last_mut() {
        *last = 1.0;
    }
}
