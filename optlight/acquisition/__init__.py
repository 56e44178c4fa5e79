"""The camera in the loop (docs/design.md §11): plan, capture, calibrate, re-plan; the photometric servo; the
dataset folder.

:func:`acquire` runs the loop::

    acquisition = optlight.acquire("default", camera="mitsuba")
    acquisition.save("datasets/face")

1. plan on the model (:func:`optlight.solve`: landmarks, placement, trajectory, verification);
2. a simulated robot executes the verified trajectory: at each capture's trigger (the dwell's start
   plus ``[trajectory] settle_s``) the joint angles are the trajectory's, and the nominal light
   frame is where pinocchio's forward kinematics of the problem's robot puts it (``light_pose``:
   position and rotation, which the lamp's calibration is relative to); the camera captures there,
   its world placing the real lamp relative to that frame;
3. the *measured* cost of the plan is the mean over its captures of the problem's objective on the
   recorded images (``setup.objective``, never the model that planned); the *modelled* cost the
   same objective on the planning model's images where that model believes the lights were (its
   light frame, moved to the calibrated lamp, at the same joint angles);
4. the model is calibrated from every usable capture so far (:func:`~optlight.capture.calibration.calibrate`)
   and the next plan made on the calibrated model (:func:`~optlight.capture.calibration.calibrated_setup`:
   its light, albedo, response and the robot's light frame on the calibrated lamp), through the same
   :func:`optlight.solve`;
5. the loop stops after ``[loop] iterations`` plans, as soon as a plan's measure is not at
   least ``[loop] tolerance`` (relative) below the best so far, or when a re-plan fails to solve or
   fails verification (the reason is the status; the first plan's is raised). The best plan by its
   measure, by the same rule (a later round replaces it only at least ``tolerance`` below), is the
   result; the first plan is the open loop's.

The measure follows the task (:func:`round_measure`, :data:`MEASURES`): landmarks, the measured cost;
a light set, the set's own measure (photometric stereo: the normal error of the normals recovered
from the recorded images against the model's; RTI: the covering radius of the captured lights; a
grid: the angle from its directions to the lights captured for them). Lower is better for each.

With a real camera (the folder camera) the loop runs in rounds, one run of the command per round
(:class:`RoundFolders`; the user's procedure is docs/camera-loop.md). Round i's plan is written to
``round_ii/`` in the acquisition folder (its trajectory.csv, joint_trajectory.yaml and captures.csv
with the trigger times), its images named ``rii_000.png`` … (:func:`round_pattern`, distinct across
rounds); the user runs the robot, saves the images there and runs the command again. That run replays
the loop: it plans round 0 again (the same problem gives the same plan), takes round 0's images,
calibrates, plans round 1 on that calibration (the same images give the same plan) and so on, each
plan checked against the captures.csv written for it, until the first round without images: it
stops with status ``awaiting captures`` and writes that round's folder. Earlier rounds' folders are
written again as they were, never the user's images.

:func:`photometric_servo` is the local loop for one light: ViSP's photometric visual servoing with
the light moving instead of the camera. The error is the measured cost J(Y) of the recorded image;
its gradient along the light sphere is the chain rule through the calibrated differentiable model,
∇_{θ,φ} J = (∂I/∂(θ, φ))ᵀ ∇_I J(Y): the image Jacobian (the interaction matrix) from the model, the
error from the measurement. The light steps by ``servo_step_deg`` against the Riemannian gradient
(metric dθ² + sin²θ dφ²), the robot reaches the new light by IK, the camera captures; a step that does
not lower the measured cost is undone and halved.
"""

from optlight.acquisition.loop import CAMERAS, LoopProgress, acquire, execute, make_camera
from optlight.acquisition.measures import MEASURES, improves, measured_costs, modelled_costs, round_measure
from optlight.acquisition.result import Acquisition, Iteration
from optlight.acquisition.rounds import (
    AWAITING,
    ROUNDS,
    RoundFolders,
    round_folder,
    round_pattern,
    round_setup,
)
from optlight.acquisition.servo import ServoResult, photometric_servo, servo_functions

__all__ = [
    "AWAITING",
    "CAMERAS",
    "MEASURES",
    "ROUNDS",
    "Acquisition",
    "Iteration",
    "LoopProgress",
    "RoundFolders",
    "ServoResult",
    "acquire",
    "execute",
    "improves",
    "make_camera",
    "measured_costs",
    "modelled_costs",
    "photometric_servo",
    "round_folder",
    "round_measure",
    "round_pattern",
    "round_setup",
    "servo_functions",
]
