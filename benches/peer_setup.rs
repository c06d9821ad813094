//! The peer set-up shared by `benches/peers.rs` and `tests/peers.rs`: the
//! bundled IRB 1600 without its tool, its nominal geometry as OPW
//! parameters for rs-opw-kinematics, and joint vectors spread over its
//! ranges.

use nalgebra::Isometry3;
use postproc::machine::Machine;
use postproc::machine::robot::Robot;
use rs_opw_kinematics::kinematics_impl::OPWKinematics;
use rs_opw_kinematics::parameters::opw_kinematics::Parameters;

/// The bundled IRB 1600 without its tool (the TCP is the flange).
pub fn irb1600() -> Robot {
    let path = format!("{}/machines/abb-irb1600.yaml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("machine file");
    let Ok(Machine::Robot(r)) = Machine::from_yaml_str(&text, &path) else {
        panic!("abb-irb1600 is not a robot")
    };
    r.with_tool(Isometry3::identity(), None)
}

/// The IRB 1600's nominal geometry (machines/abb-irb1600.yaml) as OPW
/// parameters, in metres: shoulder offset a1 = 150 mm, no forearm offset,
/// base height c1 = 486.5 mm, upper arm c2 = 700 mm, forearm c3 = 600 mm,
/// wrist to flange c4 = 65 mm; ABB's joint 3 zero is 90° from OPW's.
pub fn irb1600_opw() -> OPWKinematics {
    OPWKinematics::new(Parameters {
        a1: 0.150,
        a2: 0.0,
        b: 0.0,
        c1: 0.4865,
        c2: 0.700,
        c3: 0.600,
        c4: 0.065,
        offsets: [0.0, 0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0],
        sign_corrections: [1; 6],
        dof: 6,
    })
}

/// `n` joint vectors spread over the joint ranges (a fixed sequence).
pub fn joints(robot: &Robot, n: usize) -> Vec<[f64; 6]> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let lim = *robot.joint_limits_rad();
    (0..n)
        .map(|_| std::array::from_fn(|i| lim[i][0] + (lim[i][1] - lim[i][0]) * next()))
        .collect()
}
