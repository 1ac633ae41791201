//! `--left TOPIC --right TOPIC --odom TOPIC`: a ROS 2 bag's camera and odometry topics as the
//! input instead of the board's stream (vehicle-interfaces.md 4.1), for every command that
//! reads a vehicle log.

use replay::Ros2Topics;

/// The topics of a ROS 2 bag to read; all three or none.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct TopicArgs {
    /// A ROS 2 bag's left camera topic (sensor_msgs/msg/Image or CompressedImage): the host
    /// runs the board's detector on its images. With --right and --odom.
    #[arg(long, value_name = "TOPIC", requires_all = ["right", "odom"])]
    left: Option<String>,
    /// The bag's right camera topic. With --left and --odom.
    #[arg(long, value_name = "TOPIC", requires_all = ["left", "odom"])]
    right: Option<String>,
    /// The bag's wheel odometry topic (nav_msgs/msg/Odometry). With --left and --right.
    #[arg(long, value_name = "TOPIC", requires_all = ["left", "right"])]
    odom: Option<String>,
}

impl TopicArgs {
    /// The topics, when named.
    pub(crate) fn topics(&self) -> Option<Ros2Topics> {
        Some(Ros2Topics {
            left: self.left.clone()?,
            right: self.right.clone()?,
            odom: self.odom.clone()?,
        })
    }
}
