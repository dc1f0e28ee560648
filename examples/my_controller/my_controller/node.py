"""my_controller: a PD joint controller that joins a running hexapod graph (plain rclpy).

It answers every /hexapod/joint_states sample whose frame_id names it with a torque command
stamped like that sample: T = kp (theta_d - theta) + kd (dtheta_d - dtheta) per joint, with
the references of the same stamp from /hexapod/reference. docs/controllers.md is the contract.
"""
import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState

from hexapod_common.auth import signer  # the only project import: signs the commands

NAME = "my_controller"  # node name = controller name = frame_id of the commands
JOINTS = [f"leg{i}_{j}" for i in range(1, 7) for j in ("hip", "knee")]


def stamp_ns(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


class MyController(Node):
    def __init__(self):
        super().__init__(NAME)
        gains = {"kp_hip": 1e5, "kd_hip": 250.0, "kp_knee": 1.2e5, "kd_knee": 50.0}  # PD-P's
        g = {n: self.declare_parameter(n, v).value for n, v in gains.items()}
        self.kp = np.tile([g["kp_hip"], g["kp_knee"]], 6)  # per joint, in JOINTS order
        self.kd = np.tile([g["kd_hip"], g["kd_knee"]], 6)
        self.refs = {}  # stamp (ns) -> (theta_d, dtheta_d)
        self.waiting = None  # a state whose reference has not come yet
        self.sign = signer("/hexapod/joint_commands")
        # a deep history, as the graph's own writers keep (5000): the recorder may be up to
        # 1000 ticks behind in lockstep, and a command it has not taken yet when it rolls out
        # of a 10-deep history is missing from the bag (run_graph says so)
        self.pub = self.create_publisher(JointState, "/hexapod/joint_commands", 5000)
        # deeper queues than the default 10: references come in bursts up to 50 ticks ahead,
        # and a state must not roll out while the node catches up (answer late, not never);
        # transient-local: the references sent before this reader matched come too
        refs_qos = QoSProfile(depth=200, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(JointState, "/hexapod/reference", self.on_reference, refs_qos)
        self.create_subscription(JointState, "/hexapod/joint_states", self.on_state, 100)

    def on_reference(self, msg):
        index = [msg.name.index(j) for j in JOINTS]
        self.refs[stamp_ns(msg)] = (np.take(msg.position, index), np.take(msg.velocity, index))
        if self.waiting is not None and stamp_ns(self.waiting) in self.refs:
            state, self.waiting = self.waiting, None
            self.answer(state)

    def on_state(self, msg):
        if msg.header.frame_id.split("/")[0] != NAME:  # another controller is in charge
            return
        if stamp_ns(msg) in self.refs:
            self.answer(msg)
        else:
            self.waiting = msg

    def answer(self, state):
        k = stamp_ns(state)
        theta_d, dtheta_d = self.refs[k]
        index = [state.name.index(j) for j in JOINTS]
        theta, dtheta = np.take(state.position, index), np.take(state.velocity, index)
        torque = self.kp * (theta_d - theta) + self.kd * (dtheta_d - dtheta)
        cmd = JointState(name=JOINTS, position=theta_d.tolist(), velocity=dtheta_d.tolist(),
                         effort=torque.tolist())
        cmd.header.stamp, cmd.header.frame_id = state.header.stamp, NAME
        self.pub.publish(self.sign.message(cmd))
        self.refs = {s: r for s, r in self.refs.items() if s > k}


def main(args=None):
    rclpy.init(args=args)
    node = MyController()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
