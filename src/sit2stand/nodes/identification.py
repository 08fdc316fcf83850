"""Robot COM identification service: ``/robot/identify_com`` (sit2stand_msgs/IdentifyCom).

Request: the static-posture bag (``data_path``, written by ``sit2stand collect-postures``), the model (``planar5`` or
``full``), the held-out fraction (0: the paper's 10 %), the split seed, and where to write the parameters YAML
(empty: ``<data_path>/identified_<model>.yaml``). Response: success, message, named parameters, train/evaluation RMS
of the predicted COM against the measured COP, the CAD model's RMS on the same postures, and the condition number.
Each success also publishes the parameters on ``/robot/inertial_parameters`` (sit2stand_msgs/InertialParameters,
transient local) for other nodes.
"""

from __future__ import annotations

from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sit2stand_msgs.msg import InertialParameters
from sit2stand_msgs.srv import IdentifyCom

from ..io.topics import IDENTIFY_COM_SERVICE, ROBOT_INERTIAL_PARAMETERS_TOPIC, ros_name
from ..io.bag import BagError
from ..robot.identify import IdentificationError, identify, write_yaml
from .runtime import declare, node_main


class IdentificationNode(Node):
    """Serves /robot/identify_com (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("identification")
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.params_pub = self.create_publisher(InertialParameters, ros_name(ROBOT_INERTIAL_PARAMETERS_TOPIC),
                                                latched)
        self.robot = declare(self, "robot", "", "robot profile: packaged (`sit2stand robot list`) or a file "
                                                "(empty: TALOS)") or None
        self.create_service(IdentifyCom, ros_name(IDENTIFY_COM_SERVICE), self._on_request)
        self.get_logger().info("ready: /robot/identify_com")

    def _on_request(self, req: IdentifyCom.Request, res: IdentifyCom.Response) -> IdentifyCom.Response:
        model = req.model or "full"
        fraction = req.eval_fraction if req.eval_fraction > 0 else 0.1
        try:
            result = identify(req.data_path, model, eval_fraction=fraction, seed=int(req.seed), robot=self.robot)
        except (IdentificationError, BagError, ValueError, OSError) as err:
            res.success, res.message = False, str(err)
            self.get_logger().error(f"identification failed: {err}")
            return res
        except Exception as err:  # noqa: BLE001 - every request gets an answer; the node stays up for the next
            res.success, res.message = False, f"internal error: {err!r}"
            self.get_logger().error(f"identification failed unexpectedly: {err!r}")
            return res
        out = req.output_path or str(Path(req.data_path) / f"identified_{model}.yaml")
        write_yaml(result, out, source=req.data_path, robot=result.robot)
        res.success, res.message = True, result.summary()
        res.parameter_names = list(result.names)
        res.parameter_values = [float(v) for v in result.values]
        res.parameter_std_devs = [float(v) for v in result.std_devs]
        res.train_rms_m, res.eval_rms_m = result.train_rms_m, result.eval_rms_m
        res.cad_train_rms_m, res.cad_eval_rms_m = result.cad_train_rms_m, result.cad_eval_rms_m
        res.condition_number = float(result.condition_number)
        res.n_train, res.n_eval = result.n_train, result.n_eval
        res.output_path = out
        msg = InertialParameters(model=model, names=res.parameter_names, values=res.parameter_values,
                                 std_devs=res.parameter_std_devs, yaml_path=out)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.params_pub.publish(msg)
        self.get_logger().info(result.summary())
        return res


main = node_main(IdentificationNode)

if __name__ == "__main__":
    raise SystemExit(main())
