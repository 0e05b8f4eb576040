"""PyBullet FEM simulation shared by the dataset generator, the evaluation and the fake driver.

No rclpy here. Settings come from docs/pybullet_fem.md (measured on this machine).

Layers (imports point down only):
- the physics core, ``physics``: the material table (``MATERIALS``, from ``material``), world reset, soft-body
  parameters and loading, finger coupling, friction, static bodies, depth-buffer conversion. Every PyBullet setting that
  decides how a body behaves lives here, so the labels and the demo run the same physics.
- geometry and meshes: ``shapes``, ``library``, ``meshes`` (no PyBullet state).
- the trial protocol as one value and a trial's settings, no PyBullet: ``material`` (the material table),
  ``protocol`` (``TrialProtocol``, ``resolve_protocol``), ``trial_settings`` (``TrialSettings`` and its stored
  form; docs/dataset.md "Trial protocols").
- the grasp trials (data generator, evaluation): ``world``, ``objects``, ``hand``, ``camera``,
  ``sampler``, ``trial``.
- the simulated cell (fake Panda + RealSense driver): ``scene_spec`` and the ``cell`` package (``cell.sim_cell``
  and its parts); bringup/cell_sequence.py runs a pick-and-place sequence against a cell in one process.

API overview (stable):

- ``world``: ``connect(gui=False) -> client``; ``create_world(client, youngs_moduli_pa=(), time_step_s=None)
  -> World`` resets to a deformable world (gravity set after the reset, sparse SDF 1 cm) with a static table
  whose top is at z = 0; ``time_step_for(moduli)`` picks the stable step (5e-4 s up to 2e5 Pa, 2.5e-4 s up to
  MAX_SOFT_BODY_YOUNGS_MODULUS_PA, 1e-3 s when everything is rigid). ``World.step(n)``, ``World.set_gravity``.
- ``objects``: ``object_set("train" | "common" | "adversarial") -> [ObjectShape]``, ``get_shape(name)``,
  ``shape_from_mesh_file(path, name=None, scale=1.0)`` for a user's .obj/.stl;
  ``ObjectSpec(shape, youngs_modulus_pa, poisson_ratio=0.4, part_youngs_modulus_pa=None)`` (the second
  part's E makes a multi-material object); ``load_object(client, spec, position_xy_m, yaw_rad,
  table_top_z_m=0.0) -> LoadedObject`` (soft FEM body if E <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA, else rigid;
  ``.body_ids``, ``.parts``, ``.centroid_m()``, ``.save_state()``/``.restore_state()``, ``.is_finite()``).
  ``UnsupportedMaterial`` for combinations PyBullet cannot represent.
- ``meshes``: ``tetrahedralize(trimesh) -> TetMesh`` (fTetWild via pytetwild, coarse, cached on disk by
  content hash under $DEFGG_MESH_CACHE or ~/.cache/defgg_ros/meshes), ``convex_decomposition`` (V-HACD for
  rigid bodies), ``load_user_mesh``.
- ``camera``: ``TopDownCamera(width_px=300, height_px=300, centre_xy_m=(0, 0))`` with ``.k``,
  ``.base_T_camera``, ``.render(client) -> (depth_m, segmentation)``, ``world_to_pixel``, ``pixel_to_world``;
  ``render_object_images(client, loaded, camera) -> {depth_m, youngs_modulus_pa, object_mask, camera_k,
  base_T_camera}``.
- ``hand``: a floating Franka Hand from boxes (``create_hand(client, world_T_tcp, opening_m) -> Hand``;
  ``hand_boxes(opening_m)`` is the geometry the sampler checks).
- ``sampler``: ``sample_grasps(surface, seed, n_candidates=200, keep=None) -> [Candidate]`` (antipodal,
  top-down, hand/table collision-filtered), ``grasp_rect(world_grasp) -> GraspRect``.
- ``trial``: ``run_grasp_trial(spec, grasp: WorldGrasp, tests=("shake",) | ("shake", "twist"),
  settings=TrialSettings(), client=None, object_xy_m=(0, 0), object_yaw_rad=0) -> TrialOutcome`` with
  ``status`` (ok / lift_failed / exploded / timeout), per-direction ``shake_accels_mps2`` (16) and
  ``twist_accels_radps2`` (6 axes), ``cpu_s``.
"""
