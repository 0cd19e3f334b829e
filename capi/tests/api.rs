//! The C API called as C calls it, on a context of pathgrad's own (validation on): results, and
//! the errors that null pointers, wrong sizes, unknown names and bad ranges give.

use std::ffi::{CStr, c_char};
use std::ptr::{null, null_mut};

use pathgrad_c::*;

fn message() -> String {
    // SAFETY: the getter returns a NUL-terminated string.
    unsafe { CStr::from_ptr(pg_last_error_message()) }.to_string_lossy().into_owned()
}

/// Asserts that `status` is `want` and the message names `function` and contains `text`.
fn fails(status: PgStatus, want: PgStatus, function: &str, text: &str) {
    assert_eq!(status, want, "{}", message());
    let m = message();
    assert!(m.starts_with(function) && m.contains(text), "message {m:?} (wanted {function}: …{text}…)");
}

const PARAM: *const c_char = c"white.reflectance.value".as_ptr();

#[test]
fn own_context_renders_and_refuses_bad_arguments() {
    // SAFETY: every pointer below is valid or deliberately null; handles are destroyed once.
    unsafe {
        let mut scene = null_mut();
        fails(pg_scene_load(null(), null(), null(), 0, &mut scene), PgStatus::NullPointer, "pg_scene_load", "`spec`");
        fails(
            pg_scene_load(c"builtin:nothing".as_ptr(), null(), null(), 0, &mut scene),
            PgStatus::Scene,
            "pg_scene_load",
            "unknown built-in scene",
        );
        assert!(scene.is_null());
        let names = [c"a".as_ptr()];
        fails(
            pg_scene_load(c"builtin:cornell-box".as_ptr(), names.as_ptr(), null(), 1, &mut scene),
            PgStatus::NullPointer,
            "pg_scene_load",
            "define_values",
        );
        assert_eq!(pg_scene_load(c"builtin:cornell-box".as_ptr(), null(), null(), 0, &mut scene), PgStatus::Ok);
        let count = pg_scene_param_count(scene);
        assert!(count > 0 && !pg_scene_param_name(scene, 0).is_null() && pg_scene_param_name(scene, count).is_null());
        let mut info = PgParamInfo::default();
        assert_eq!(pg_scene_param_info(scene, PARAM, &mut info), PgStatus::Ok);
        assert_eq!(info.count, 3);
        let mut three = [0.0f32; 3];
        fails(
            pg_scene_get_param(scene, PARAM, three.as_mut_ptr(), 2),
            PgStatus::InvalidArgument,
            "pg_scene_get_param",
            "holds 2",
        );
        fails(pg_scene_get_param(scene, PARAM, null_mut(), 3), PgStatus::NullPointer, "pg_scene_get_param", "`values`");
        fails(
            pg_scene_set_param(scene, c"nope".as_ptr(), three.as_ptr(), 3),
            PgStatus::InvalidArgument,
            "pg_scene_set_param",
            "no parameter 'nope'",
        );
        let outside = [2.0f32; 3];
        fails(
            pg_scene_set_param(scene, PARAM, outside.as_ptr(), 3),
            PgStatus::InvalidArgument,
            "pg_scene_set_param",
            "",
        );
        let grey = [0.5f32; 3];
        assert_eq!(pg_scene_set_param(scene, PARAM, grey.as_ptr(), 3), PgStatus::Ok);
        assert_eq!(pg_scene_get_param(scene, PARAM, three.as_mut_ptr(), 3), PgStatus::Ok);
        assert_eq!(three, grey);

        let mut ctx = null_mut();
        fails(pg_context_create(null(), null_mut()), PgStatus::NullPointer, "pg_context_create", "`out`");
        let desc = PgContextDesc { device: c"nonsense-device".as_ptr(), validation: 1 };
        fails(pg_context_create(&desc, &mut ctx), PgStatus::NoDevice, "pg_context_create", "nonsense-device");
        let desc = PgContextDesc { device: c"cpu".as_ptr(), validation: 1 };
        assert_eq!(pg_context_create(&desc, &mut ctx), PgStatus::Ok, "{}", message());
        let mut lent = null_mut();
        fails(pg_context_from_vulkan(null(), &mut lent), PgStatus::NullPointer, "pg_context_from_vulkan", "`lent`");

        let mut renderer = null_mut();
        fails(pg_renderer_create(ctx, null(), &mut renderer), PgStatus::NullPointer, "pg_renderer_create", "`scene`");
        assert_eq!(pg_renderer_create(ctx, scene, &mut renderer), PgStatus::Ok, "{}", message());
        let mut frame = null_mut();
        let bad = PgFrameDesc { max_depth: -2, ..PgFrameDesc::default() };
        fails(pg_frame_create(renderer, &bad, &mut frame), PgStatus::InvalidArgument, "pg_frame_create", "max_depth");
        let fd = PgFrameDesc { width: 16, height: 12, spp: 2, seed: 3, ..PgFrameDesc::default() };
        assert_eq!(pg_frame_create(renderer, &fd, &mut frame), PgStatus::Ok, "{}", message());
        let mut resolved = PgFrameDesc::default();
        assert_eq!(pg_frame_desc(frame, &mut resolved), PgStatus::Ok);
        assert_eq!((resolved.width, resolved.height, resolved.spp), (16, 12, 2));
        assert!(resolved.max_depth > 0);

        let mut view = PgBufferView { buffer: 0, offset: 0, size: 0, layout: PgLayout::ParamValues, fixed_unit: 0.0 };
        fails(pg_frame_buffer(frame, 9, &mut view), PgStatus::InvalidArgument, "pg_frame_buffer", "kind 9");
        assert_eq!(pg_frame_buffer(frame, PG_BUFFER_IMAGE, &mut view), PgStatus::Ok);
        assert!(view.buffer != 0 && view.size >= 16 * 12 * 12 && view.layout == PgLayout::RgbSums);
        fails(
            pg_frame_record_render(frame, null_mut(), 0, 2),
            PgStatus::NullPointer,
            "pg_frame_record_render",
            "command_buffer",
        );
        fails(pg_frame_render(frame, 0, 3), PgStatus::InvalidArgument, "pg_frame_render", "0..2");

        // A render on pathgrad's own queue equals the CPU reference's up to rounding.
        let n = 16 * 12 * 3;
        let (mut gpu, mut cpu) = (vec![0.0f32; n], vec![0.0f32; n]);
        assert_eq!(pg_frame_clear(frame), PgStatus::Ok);
        assert_eq!(pg_frame_render(frame, 0, 2), PgStatus::Ok, "{}", message());
        fails(
            pg_frame_read_image(frame, 2, gpu.as_mut_ptr(), n - 1),
            PgStatus::InvalidArgument,
            "pg_frame_read_image",
            "",
        );
        assert_eq!(pg_frame_read_image(frame, 2, gpu.as_mut_ptr(), n), PgStatus::Ok);
        assert_eq!(pg_scene_render_cpu(scene, &fd, cpu.as_mut_ptr(), n), PgStatus::Ok);
        let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
        assert!(mean(&gpu) > 0.01 && (mean(&gpu) - mean(&cpu)).abs() <= 1e-3 * mean(&cpu));

        // The gradient of the image's mean by the white walls' reflectance is positive.
        let adjoint = vec![1.0 / n as f32; n];
        fails(
            pg_frame_write_adjoint(frame, adjoint.as_ptr(), 5),
            PgStatus::InvalidArgument,
            "pg_frame_write_adjoint",
            "",
        );
        assert_eq!(pg_frame_write_adjoint(frame, adjoint.as_ptr(), n), PgStatus::Ok);
        assert_eq!(pg_frame_backward(frame, 0, 2), PgStatus::Ok, "{}", message());
        assert_eq!(pg_frame_check_status(frame), PgStatus::Ok);
        let mut gradient = vec![0.0f32; pg_scene_value_count(scene)];
        assert_eq!(pg_frame_read_gradients(frame, gradient.as_mut_ptr(), gradient.len()), PgStatus::Ok);
        let white: f32 = gradient[info.offset..info.offset + 3].iter().sum();
        assert!(white > 0.0 && gradient.iter().all(|g| g.is_finite()), "{white}");

        assert_eq!(pg_context_validation_messages(ctx), 0);
        // Any order of destruction: the frame keeps its renderer and context.
        pg_context_destroy(ctx);
        pg_renderer_destroy(renderer);
        pg_scene_destroy(scene);
        assert_eq!(pg_frame_render(frame, 0, 1), PgStatus::Ok, "{}", message());
        pg_frame_destroy(frame);
        pg_frame_destroy(null_mut());
        pg_context_destroy(null_mut());
    }
}

/// A frame with `attached` set differentiates a glass sphere's index of refraction (over a diffuse
/// floor: `tests/data/scenes/attached_floor.xml`), as the library's CPU reference does with the same
/// seed and samples, in float and in fixed point (`deterministic`); a detached frame leaves it 0,
/// and a Jacobian noise without `attached` is refused by the desc's field names.
#[test]
fn an_attached_frame_differentiates_the_index_of_refraction() {
    use pathgrad::integrator::{RenderOptions, Sampling};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/scenes/attached_floor.xml\0");
    let spec = CStr::from_bytes_with_nul(path.as_bytes()).unwrap();
    let eta = c"glass.bsdf.eta";
    // SAFETY: every pointer below is valid; handles are destroyed once.
    unsafe {
        let mut scene = null_mut();
        assert_eq!(pg_scene_load(spec.as_ptr(), null(), null(), 0, &mut scene), PgStatus::Ok, "{}", message());
        let mut info = PgParamInfo::default();
        assert_eq!(pg_scene_param_info(scene, eta.as_ptr(), &mut info), PgStatus::Ok, "{}", message());
        let mut ctx = null_mut();
        let desc = PgContextDesc { device: c"cpu".as_ptr(), validation: 1 };
        assert_eq!(pg_context_create(&desc, &mut ctx), PgStatus::Ok, "{}", message());
        let mut renderer = null_mut();
        assert_eq!(pg_renderer_create(ctx, scene, &mut renderer), PgStatus::Ok, "{}", message());

        let base = PgFrameDesc { width: 16, height: 12, spp: 2, seed: 5, ..PgFrameDesc::default() };
        let mut frame = null_mut();
        let noise = PgFrameDesc { jacobian_noise: 0.5, ..base };
        fails(pg_frame_create(renderer, &noise, &mut frame), PgStatus::InvalidArgument, "pg_frame_create", "attached");

        let n = 16 * 12 * 3;
        let adjoint: Vec<f32> = (0..n).map(|i| 1.0 + (i % 7) as f32 / 7.0).collect();
        let gradient_of = |desc: &PgFrameDesc| {
            let mut frame = null_mut();
            assert_eq!(pg_frame_create(renderer, desc, &mut frame), PgStatus::Ok, "{}", message());
            let mut resolved = PgFrameDesc::default();
            assert_eq!(pg_frame_desc(frame, &mut resolved), PgStatus::Ok);
            assert_eq!(resolved.attached, desc.attached);
            assert_eq!(pg_frame_render(frame, 0, 2), PgStatus::Ok, "{}", message());
            assert_eq!(pg_frame_write_adjoint(frame, adjoint.as_ptr(), n), PgStatus::Ok);
            assert_eq!(pg_frame_backward(frame, 0, 2), PgStatus::Ok, "{}", message());
            assert_eq!(pg_frame_check_status(frame), PgStatus::Ok, "{}", message());
            let mut gradient = vec![0.0f32; pg_scene_value_count(scene)];
            assert_eq!(pg_frame_read_gradients(frame, gradient.as_mut_ptr(), gradient.len()), PgStatus::Ok);
            pg_frame_destroy(frame);
            gradient[info.offset]
        };
        assert_eq!(gradient_of(&base), 0.0, "detached sampling does not differentiate η");
        let attached = gradient_of(&PgFrameDesc { attached: 1, ..base });

        let loaded = pathgrad::scene::load(&path[..path.len() - 1], &[]).unwrap();
        let options = RenderOptions {
            width: 16,
            height: 12,
            spp: 2,
            seed: 5,
            sampling: Sampling::attached(),
            ..RenderOptions::for_scene(&loaded)
        };
        let weights = pathgrad::image::Image::from_rgb(16, 12, adjoint.clone()).unwrap();
        let reference = pathgrad::cpu::backward(&loaded, &options, &weights).unwrap()[info.offset] as f32;
        assert!(reference.abs() > 0.1, "the CPU reference's η gradient is {reference}");
        assert!((attached - reference).abs() <= 2e-3 * reference.abs(), "frame {attached}, CPU reference {reference}");
        let fixed = gradient_of(&PgFrameDesc { attached: 1, deterministic: 1, ..base });
        assert!((fixed - reference).abs() <= 2e-3 * reference.abs(), "fixed-point frame {fixed}, CPU {reference}");

        assert_eq!(pg_context_validation_messages(ctx), 0);
        pg_renderer_destroy(renderer);
        pg_context_destroy(ctx);
        pg_scene_destroy(scene);
    }
}
