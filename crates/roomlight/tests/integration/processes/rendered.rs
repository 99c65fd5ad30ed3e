//! The rendered room served by `roomlight sim`, images in and out over gRPC.

use super::*;

/// `roomlight sim --scene small` serves the rendered room: a client shows a projector image,
/// switches the LEDs and captures camera images over gRPC, and what it gets is the simulator's
/// own render (to within the camera noise); bad images, projectors and presets are refused with
/// messages that name them.
#[test]
fn the_rendered_room_is_served_images_in_and_out() {
    use roomlight_proto::v1;
    let dir = tempfile::tempdir().expect("temp dir");
    let mut procs = Procs(Vec::new());
    let out = procs.spawn(
        "sim",
        &[
            "sim",
            "--scene",
            "small",
            "--listen",
            "127.0.0.1:0",
            "--seed",
            "3",
        ],
        dir.path(),
    );
    let address = address(&wait_line(&out, Duration::from_secs(60), |l| {
        l.starts_with("sim listening on")
    }));
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let mut client =
            v1::rendered_room_client::RenderedRoomClient::connect(format!("http://{address}"))
                .await
                .expect("connect")
                .max_decoding_message_size(256 << 20)
                .max_encoding_message_size(256 << 20);
        let room = client
            .describe(v1::DescribeRequest {})
            .await
            .expect("describe")
            .into_inner();
        assert_eq!(room.room, "small");
        assert_eq!(room.presets, ["on"]);
        let left = room
            .projectors
            .iter()
            .find(|p| p.name == "left")
            .expect("projector left");
        let (w, h) = (left.width, left.height);
        let camera = client.clone();
        let capture = async || -> Vec<f32> {
            let image = camera
                .clone()
                .capture_image(v1::CaptureRequest {})
                .await
                .expect("capture")
                .into_inner();
            assert_eq!(
                (image.width, image.height),
                (room.camera_width, room.camera_height)
            );
            image
                .linear_f32le
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
        let dark = mean(&capture().await);
        client
            .set_lights(v1::SetLightsRequest {
                preset: "on".into(),
            })
            .await
            .expect("lights on");
        let lit = mean(&capture().await);
        assert!(lit > 5.0 * dark.max(1e-6), "LEDs on {lit} vs off {dark}");
        client
            .set_lights(v1::SetLightsRequest {
                preset: String::new(),
            })
            .await
            .expect("lights off");
        client
            .show_image(v1::ShowImageRequest {
                projector: "left".into(),
                width: w,
                height: h,
                rgb8: vec![255; (w * h * 3) as usize],
            })
            .await
            .expect("show");
        let served = mean(&capture().await);
        // The same frame rendered here, without noise.
        let scene = roomlight_sim::scenes::small().expect("small");
        let local = roomlight_sim::Room::build(scene).expect("room");
        let frames: Vec<roomlight_sim::Frame> = local
            .scene()
            .projectors
            .iter()
            .map(|p| {
                if p.name == "left" {
                    roomlight_sim::Frame::Uniform([1.0; 3])
                } else {
                    roomlight_sim::Frame::Black
                }
            })
            .collect();
        let expected = local.render(&frames, None).expect("render");
        let expected = mean(
            &expected
                .pixels
                .iter()
                .flatten()
                .copied()
                .collect::<Vec<f32>>(),
        );
        assert!(
            (served - expected).abs() < 0.02 * expected,
            "served {served} vs rendered {expected}"
        );
        let refused = |status: tonic::Status, code: tonic::Code, words: &[&str]| {
            assert_eq!(status.code(), code, "{status}");
            for w in words {
                assert!(status.message().contains(w), "{status} lacks {w}");
            }
        };
        let wrong_size = client
            .show_image(v1::ShowImageRequest {
                projector: "left".into(),
                width: 10,
                height: 10,
                rgb8: vec![0; 300],
            })
            .await
            .expect_err("wrong size");
        refused(
            wrong_size,
            tonic::Code::InvalidArgument,
            &["left", &format!("{w}×{h}")],
        );
        let unknown = client
            .show_image(v1::ShowImageRequest {
                projector: "nope".into(),
                width: w,
                height: h,
                rgb8: vec![0; (w * h * 3) as usize],
            })
            .await
            .expect_err("unknown projector");
        refused(unknown, tonic::Code::NotFound, &["nope", "left"]);
        let preset = client
            .set_lights(v1::SetLightsRequest {
                preset: "disco".into(),
            })
            .await
            .expect_err("unknown preset");
        refused(preset, tonic::Code::NotFound, &["disco", "on"]);
    });
    drop(procs);
}
