/* The per-control-step hot path of opend-mj's environments and Task, in C.
 *
 * One call per control step does what the Python step does (`ActionAdapter.delta_parts`,
 * `OpenCabinetTask.apply_action` with `MocapPathPlanner.plan`, `OpenCabinetTask.fast_substeps`,
 * `SceneReader.fill` with `HandTouch.vector_from` and `RewardProbe.read`), with the same float64
 * operations in the same order, so that observations, rewards and the whole mjData are the same to
 * the bit:
 *   - compiled with -ffp-contract=off (no fused multiply-adds where Python rounds twice) and without
 *     -ffast-math; x86-64 and arm64 evaluate doubles in double precision;
 *   - dot products through the same BLAS ddot that numpy's `a.dot(b)` calls (its pointer is handed in
 *     by the loader, which checks it against numpy at load time);
 *   - sin, cos, acos and sqrt from libm, which Python's math module and numpy's float64 sin and cos
 *     call here (the loader checks numpy's against libm's);
 *   - Python's comparisons kept literally: `max(0.0, x)` is `x > 0.0 ? x : 0.0`, `min(1.0, x)` is
 *     `x < 1.0 ? x : 1.0`, numpy's clip of finite numbers is `min(max(x, lo), hi)`.
 * Anything the Python step does differently on rare paths (a non-finite action or grasp-site
 * position, a changed handle box) is reported in the status bits and left to the Python code.
 *
 * Units: metres, radians, seconds; quaternions w, x, y, z.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define OFS_MAX_SUBSTEPS 64
#define OFS_MAX_HANDLE_BODIES 8

/* status bits returned by ofs_env_step / ofs_fill / ofs_apply / ofs_substeps */
#define OFS_WARN_BADQACC 1    /* the instability warnings, in `task._INSTABILITY_WARNINGS` order */
#define OFS_WARN_BADQPOS 2
#define OFS_WARN_BADQVEL 4
#define OFS_NAN 8             /* no warning but a non-finite qpos */
#define OFS_LAST 16           /* time >= the time limit */
#define OFS_BOX_STALE 32      /* the handle bodies moved: the caller computes the box, then ofs_fill */
#define OFS_BAD_ACTION 64     /* a non-finite action: nothing was changed (Python raises) */
#define OFS_ZERO_QUAT 128     /* a zero-norm root quaternion: nothing was changed (Python raises) */
#define OFS_DISTANCE 256      /* a non-finite grasp site or box: the caller computes the distance */

typedef double (*ofs_ddot64)(int64_t, const double *, int64_t, const double *, int64_t);
typedef double (*ofs_ddot32)(int32_t, const double *, int32_t, const double *, int32_t);

/* Everything one step reads and writes; filled in by opend_mj.sim.fast.binding (ctypes mirror: every
 * field is 8 bytes wide, so there is no padding). Pointers into numpy arrays stay valid while the
 * Python binding holds them; mjModel / mjData are the scene's own. */
typedef struct {
  const mjModel *m;
  mjData *d;
  void *ddot;               /* BLAS ddot (numpy's), or NULL: plain left-to-right sum */
  int64_t ddot_ilp64;       /* 1: 64-bit integer arguments */
  /* ---- task: mocap path and finger controls (OpenCabinetTask.apply_action) */
  int64_t substeps;         /* physics steps per control step */
  int64_t mocap_id;
  int64_t n_fingers;
  const int64_t *ctrl_index;          /* [n_fingers] actuator ids */
  const double *ctrl_lo, *ctrl_hi;    /* [n_fingers] their ctrlrange */
  const double *workspace;            /* [6] low x y z, high x y z (m) */
  const double *travel;               /* [substeps] k * max travel per substep (m) */
  const double *turn;                 /* [substeps] k * max angle per substep (rad) */
  int64_t warn_ids[3];                /* mjtWarning of BADQACC, BADQPOS, BADQVEL */
  double time_limit;                  /* s */
  /* path of the current control step */
  int64_t has_pos, has_quat, writes;
  double path_pos[OFS_MAX_SUBSTEPS * 3];
  double path_quat[OFS_MAX_SUBSTEPS * 4];
  double root_target[7];              /* clipped position, unit quaternion */
  /* ---- actions */
  double *action;                     /* [6 + n] delta or [7 + n] absolute action, float64 */
  double *native;                     /* [7 + n] the task's action the step applies */
  double step_pos, step_rot;          /* m and rad per unit delta action */
  const double *finger_low, *half_span; /* [n_fingers] */
  /* ---- observations (SceneReader.fill): offsets into out, -1 where absent */
  double *out;
  int64_t n_hand_joints;
  const int64_t *hand_qpos_adr, *hand_dof_adr; /* [n_hand_joints] */
  int64_t off_hand_qpos, off_hand_qvel, off_root_pos, off_root_quat, off_root_vel;
  int64_t off_site_pos, off_site_quat, off_mocap_pos, off_mocap_quat, off_touch, off_time;
  int64_t off_handle_pos, off_handle_size, off_open_ratio;
  int64_t root_body, site, free_dof;
  /* ---- touch (HandTouch) */
  int64_t n_parts;
  const uint8_t *touch_hand_geom;     /* [ngeom] 1: a geom of the hand model's bodies */
  const int64_t *part_of_geom;        /* [ngeom] */
  int64_t elliptic;
  /* ---- reward terms (RewardProbe.read) */
  const uint8_t *probe_hand_geom;     /* [ngeom] 1: a geom of the hand's kinematic tree */
  const uint8_t *handle_geom;         /* [ngeom] 1: a handle geom of the instructed target */
  int64_t n_targets;
  const int64_t *target_adr;          /* [n_targets] qpos addresses */
  const double *target_closed, *target_sign, *target_span; /* [n_targets] closed value, open sign, range span */
  int64_t target_index;               /* the instructed target's index in those */
  double target_closed_value, target_sign_value, open_span, range_span;
  double threshold, moved_threshold;
  int64_t n_handle_bodies;
  const int64_t *handle_bodies;       /* [n_handle_bodies] */
  int64_t box_valid;                  /* 0: box_key holds nothing yet */
  double box_key[OFS_MAX_HANDLE_BODIES * 7]; /* those bodies' xpos and xquat when box was computed */
  double box[6];                      /* the instructed handle's world box: lo x y z, hi x y z */
  /* ---- outputs */
  double terms[7];  /* distance, contact, open_ratio, others_range, success, others_moved, range_ratio */
} ofs_ctx;

/* numpy's `a.dot(b)` of two contiguous float64 vectors */
static double dot(const ofs_ctx *c, const double *a, const double *b, int n) {
  if (c->ddot) {
    if (c->ddot_ilp64) return ((ofs_ddot64)c->ddot)(n, a, 1, b, 1);
    return ((ofs_ddot32)c->ddot)(n, a, 1, b, 1);
  }
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

/* exposed for the loader's check against numpy's dot */
double ofs_dot(const ofs_ctx *c, const double *a, const double *b, int64_t n) { return dot(c, a, b, (int)n); }

/* ---------------------------------------------------------------- actions */

/* ActionAdapter.delta_parts: c->action (6 + n, in [-1, 1] after clipping) -> c->native (7 + n).
 * Returns OFS_BAD_ACTION where the task's action would have a non-finite number. */
static int delta_native(ofs_ctx *c) {
  const int n = (int)c->n_fingers;
  double v[6 + 64];
  for (int i = 0; i < 6 + n; i++) {  /* np.minimum(np.maximum(a, -1), 1): NaN passes through */
    double a = c->action[i];
    if (a != a) { v[i] = a; continue; }
    a = a >= -1.0 ? a : -1.0;
    v[i] = a <= 1.0 ? a : 1.0;
  }
  const double *mp = c->d->mocap_pos + 3 * c->mocap_id, *mq = c->d->mocap_quat + 4 * c->mocap_id;
  double *pos = c->native, *quat = c->native + 3, *fingers = c->native + 7;
  const double sp = c->step_pos, sr = c->step_rot;
  double rotvec[3] = {v[3] * sr, v[4] * sr, v[5] * sr};
  double angle = sqrt(dot(c, rotvec, rotvec, 3));
  if (angle > 1e-12) {
    double ax = rotvec[0], ay = rotvec[1], az = rotvec[2];
    double axis[3] = {ax / angle, ay / angle, az / angle};
    double norm = sqrt(dot(c, axis, axis, 3));
    double half = angle / 2;
    double s = sin(half);
    double w1 = cos(half), x1 = s * (ax / angle / norm), y1 = s * (ay / angle / norm), z1 = s * (az / angle / norm);
    double w2 = mq[0], x2 = mq[1], y2 = mq[2], z2 = mq[3];
    quat[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2;
    quat[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2;
    quat[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2;
    quat[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2;
    double qn = sqrt(dot(c, quat, quat, 4));
    for (int i = 0; i < 4; i++) quat[i] /= qn;
  } else {
    for (int i = 0; i < 4; i++) quat[i] = mq[i];
  }
  for (int i = 0; i < n; i++) fingers[i] = c->finger_low[i] + (v[6 + i] + 1.0) * c->half_span[i];
  for (int i = 0; i < 3; i++) pos[i] = mp[i] + v[i] * sp;
  for (int i = 0; i < 7 + n; i++)
    if (!isfinite(c->native[i])) return OFS_BAD_ACTION;
  return 0;
}

/* ---------------------------------------------------------------- mocap path */

/* MocapPathPlanner.slerp from q toward t (both copied, any norm); returns the writes */
static int64_t slerp(ofs_ctx *c, const double *q_in, const double *t_in) {
  const int64_t n = c->substeps;
  double q0 = q_in[0], q1 = q_in[1], q2 = q_in[2], q3 = q_in[3];
  double norm = sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3);
  q0 = q0 / norm, q1 = q1 / norm, q2 = q2 / norm, q3 = q3 / norm;
  double t0 = t_in[0], t1 = t_in[1], t2 = t_in[2], t3 = t_in[3];
  norm = sqrt(t0 * t0 + t1 * t1 + t2 * t2 + t3 * t3);
  t0 = t0 / norm, t1 = t1 / norm, t2 = t2 / norm, t3 = t3 / norm;
  double d = q0 * t0 + q1 * t1 + q2 * t2 + q3 * t3;
  if (d < 0) t0 = -t0, t1 = -t1, t2 = -t2, t3 = -t3, d = -d;  /* the shorter way round */
  double angle = 2 * acos(d < 1.0 ? d : 1.0);
  double *rows = c->path_quat;
  if (angle < 1e-9) {
    for (int64_t k = 0; k < n; k++) rows[4 * k] = t0, rows[4 * k + 1] = t1, rows[4 * k + 2] = t2, rows[4 * k + 3] = t3;
    return 1;
  }
  double half = angle / 2, sin_half = sin(half);
  for (int64_t k = 0; k < n; k++) {
    double t = c->turn[k] / angle;
    if (t > 1.0) t = 1.0;
    double a = sin((1 - t) * half) / sin_half, b = sin(t * half) / sin_half;
    double x0 = a * q0 + b * t0, x1 = a * q1 + b * t1, x2 = a * q2 + b * t2, x3 = a * q3 + b * t3;
    double xn = sqrt(x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3);
    double *row = rows + 4 * k;
    row[0] = x0 / xn, row[1] = x1 / xn, row[2] = x2 / xn, row[3] = x3 / xn;
    if (t == 1.0) {  /* every later substep repeats this row */
      for (int64_t j = k + 1; j < n; j++) memcpy(rows + 4 * j, row, 4 * sizeof(double));
      return k + 1;
    }
  }
  return n;
}

/* OpenCabinetTask.apply_action for c->native: clip the root target to the workspace, plan the
 * mocap's path (MocapPathPlanner.plan), set the finger controls. */
int64_t ofs_apply(ofs_ctx *c) {
  const double *pos = c->native, *quat = c->native + 3, *fingers = c->native + 7;
  double norm = sqrt(dot(c, quat, quat, 4));
  if (norm < 1e-6) return OFS_ZERO_QUAT;
  double p[3] = {pos[0], pos[1], pos[2]};
  const double *lo = c->workspace, *hi = c->workspace + 3;
  if (!(lo[0] < p[0] && p[0] < hi[0] && lo[1] < p[1] && p[1] < hi[1] && lo[2] < p[2] && p[2] < hi[2]))
    for (int i = 0; i < 3; i++) {  /* np.minimum(np.maximum(pos, lo), hi) */
      double x = p[i];
      if (x != x) continue;
      x = x >= lo[i] ? x : lo[i];
      p[i] = x <= hi[i] ? x : hi[i];
    }
  double *target = c->root_target;
  for (int i = 0; i < 3; i++) target[i] = p[i];
  for (int i = 0; i < 4; i++) target[3 + i] = quat[i] / norm;
  /* the plan */
  mjData *d = c->d;
  double *mp = d->mocap_pos + 3 * c->mocap_id, *mq = d->mocap_quat + 4 * c->mocap_id;
  const int64_t n = c->substeps;
  double px = mp[0], py = mp[1], pz = mp[2];
  double delta[3] = {target[0] - px, target[1] - py, target[2] - pz};
  double dist = sqrt(dot(c, delta, delta, 3));
  int64_t writes = 0;
  c->has_pos = 0;
  if (dist > 1e-12) {
    double ux = delta[0] / dist, uy = delta[1] / dist, uz = delta[2] / dist;
    double *rows = c->path_pos;
    for (int64_t k = 0; k < n; k++) {
      double travel = c->travel[k];
      double *row = rows + 3 * k;
      if (travel < dist) {
        row[0] = px + ux * travel, row[1] = py + uy * travel, row[2] = pz + uz * travel;
        writes = k + 1;
      } else {  /* arrives: this row and every later one */
        row[0] = px + ux * dist, row[1] = py + uy * dist, row[2] = pz + uz * dist;
        writes = k + 1;
        for (int64_t j = k + 1; j < n; j++) memcpy(rows + 3 * j, row, 3 * sizeof(double));
        break;
      }
    }
    c->has_pos = 1;
  }
  double cosine = dot(c, mq, target + 3, 4);
  c->has_quat = 0;
  if (fabs(cosine) > 1.0 - 1e-12) {  /* no rotation: the mocap takes the target quaternion now */
    memcpy(mq, target + 3, 4 * sizeof(double));
  } else {
    double q[4] = {mq[0], mq[1], mq[2], mq[3]};
    int64_t quat_writes = slerp(c, q, target + 3);
    if (quat_writes > writes) writes = quat_writes;
    c->has_quat = 1;
  }
  c->writes = (c->has_pos || c->has_quat) ? writes : 0;
  /* the finger controls: np.minimum(np.maximum(fingers, lo), hi) */
  for (int64_t i = 0; i < c->n_fingers; i++) {
    double x = fingers[i];
    if (x == x) {
      x = x >= c->ctrl_lo[i] ? x : c->ctrl_lo[i];
      x = x <= c->ctrl_hi[i] ? x : c->ctrl_hi[i];
    }
    d->ctrl[c->ctrl_index[i]] = x;
  }
  return 0;
}

/* the planned path's row i into the mocap (composer's per-substep hook, `before_substep`) */
void ofs_write_row(ofs_ctx *c, int64_t i) {
  if (i < 0 || i >= c->substeps) return;  /* no row: composer stepping more substeps than planned */
  if (c->has_pos) memcpy(c->d->mocap_pos + 3 * c->mocap_id, c->path_pos + 3 * i, 3 * sizeof(double));
  if (c->has_quat) memcpy(c->d->mocap_quat + 4 * c->mocap_id, c->path_quat + 4 * i, 4 * sizeof(double));
}

/* OpenCabinetTask.fast_substeps: the path's rows with one mj_step each while the mocap moves, the
 * rest in one go; then kinematics (cameras: also com, cameras and lights). Returns warning bits. */
int64_t ofs_substeps(ofs_ctx *c, int64_t cameras) {
  const mjModel *m = c->m;
  mjData *d = c->d;
  int before[3];
  for (int i = 0; i < 3; i++) before[i] = d->warning[c->warn_ids[i]].number;
  for (int64_t i = 0; i < c->writes; i++) {
    ofs_write_row(c, i);
    mj_step(m, d);
  }
  for (int64_t i = c->writes; i < c->substeps; i++) mj_step(m, d);
  mj_kinematics(m, d);
  if (cameras) {
    mj_comPos(m, d);
    mj_camlight(m, d);
  }
  int64_t bits = 0;
  for (int i = 0; i < 3; i++)
    if (d->warning[c->warn_ids[i]].number > before[i]) bits |= (int64_t)1 << i;
  return bits;
}

/* ---------------------------------------------------------------- observations and reward terms */

/* transforms.mat9_to_quat: unit quaternion (w >= 0) of a row-major rotation matrix into q */
static void mat9_to_quat(const ofs_ctx *c, const double *m9, double *q) {
  double m00 = m9[0], m01 = m9[1], m02 = m9[2], m10 = m9[3], m11 = m9[4], m12 = m9[5], m20 = m9[6], m21 = m9[7],
         m22 = m9[8];
  double t = m00 + m11 + m22, s;
  if (t > 0) {
    s = sqrt(t + 1.0) * 2;
    q[0] = 0.25 * s, q[1] = (m21 - m12) / s, q[2] = (m02 - m20) / s, q[3] = (m10 - m01) / s;
  } else if (m00 > m11 && m00 > m22) {
    s = sqrt(1.0 + m00 - m11 - m22) * 2;
    q[0] = (m21 - m12) / s, q[1] = 0.25 * s, q[2] = (m01 + m10) / s, q[3] = (m02 + m20) / s;
  } else if (m11 > m22) {
    s = sqrt(1.0 + m11 - m00 - m22) * 2;
    q[0] = (m02 - m20) / s, q[1] = (m01 + m10) / s, q[2] = 0.25 * s, q[3] = (m12 + m21) / s;
  } else {
    s = sqrt(1.0 + m22 - m00 - m11) * 2;
    q[0] = (m10 - m01) / s, q[1] = (m02 + m20) / s, q[2] = (m12 + m21) / s, q[3] = 0.25 * s;
  }
  double norm = sqrt(dot(c, q, q, 4));
  for (int i = 0; i < 4; i++) q[i] /= norm;
  if (q[0] < 0)
    for (int i = 0; i < 4; i++) q[i] = -q[i];
}

/* the handle bodies' poses now equal those the box was computed for (RewardProbe.target_box's key) */
static int box_fresh(const ofs_ctx *c) {
  if (!c->box_valid) return 0;
  for (int64_t b = 0; b < c->n_handle_bodies; b++) {
    int64_t id = c->handle_bodies[b];
    if (memcmp(c->box_key + 7 * b, c->d->xpos + 3 * id, 3 * sizeof(double)) ||
        memcmp(c->box_key + 7 * b + 3, c->d->xquat + 4 * id, 4 * sizeof(double)))
      return 0;
  }
  return 1;
}

/* SceneReader.fill + HandTouch.vector_from + RewardProbe.read. box_given: c->box was just set by the
 * caller for the current poses (they become its key); otherwise a moved handle returns
 * OFS_BOX_STALE and nothing is written. */
int64_t ofs_fill(ofs_ctx *c, int64_t privileged, int64_t box_given) {
  const mjModel *m = c->m;
  const mjData *d = c->d;
  if (box_given) {
    for (int64_t b = 0; b < c->n_handle_bodies; b++) {
      int64_t id = c->handle_bodies[b];
      memcpy(c->box_key + 7 * b, d->xpos + 3 * id, 3 * sizeof(double));
      memcpy(c->box_key + 7 * b + 3, d->xquat + 4 * id, 4 * sizeof(double));
    }
    c->box_valid = 1;
  } else if (!box_fresh(c)) {
    return OFS_BOX_STALE;
  }
  double *out = c->out;
  for (int64_t i = 0; i < c->n_hand_joints; i++) {
    out[c->off_hand_qpos + i] = d->qpos[c->hand_qpos_adr[i]];
    out[c->off_hand_qvel + i] = d->qvel[c->hand_dof_adr[i]];
  }
  memcpy(out + c->off_root_pos, d->xpos + 3 * c->root_body, 3 * sizeof(double));
  memcpy(out + c->off_root_quat, d->xquat + 4 * c->root_body, 4 * sizeof(double));
  memcpy(out + c->off_root_vel, d->qvel + c->free_dof, 6 * sizeof(double));
  memcpy(out + c->off_site_pos, d->site_xpos + 3 * c->site, 3 * sizeof(double));
  memcpy(out + c->off_mocap_pos, d->mocap_pos + 3 * c->mocap_id, 3 * sizeof(double));
  memcpy(out + c->off_mocap_quat, d->mocap_quat + 4 * c->mocap_id, 4 * sizeof(double));
  mat9_to_quat(c, d->site_xmat + 9 * c->site, out + c->off_site_quat);
  out[c->off_time] = d->time;
  const double *lo = c->box, *hi = c->box + 3;
  /* the reward terms from the target joints (checker.check_values without its dict) */
  double q = 0.0, others_range = 0.0;
  int others = 0;
  for (int64_t i = 0; i < c->n_targets; i++) {
    double value = d->qpos[c->target_adr[i]];
    if (i == c->target_index) {
      q = value;
    } else {
      double x = (value - c->target_closed[i]) * c->target_sign[i];
      double ratio = (x > 0.0 ? x : 0.0) / c->target_span[i];
      others_range = others ? (ratio > others_range ? ratio : others_range) : ratio;
      others = 1;
    }
  }
  double x = (q - c->target_closed_value) * c->target_sign_value;
  double opening = x > 0.0 ? x : 0.0;
  double open_ratio = opening / c->open_span;
  if (privileged) {
    for (int i = 0; i < 3; i++) {
      out[c->off_handle_pos + i] = (lo[i] + hi[i]) / 2;
      out[c->off_handle_size + i] = hi[i] - lo[i];
    }
    out[c->off_open_ratio] = open_ratio;
  }
  /* touch and the contact term from one pass over the contacts */
  double *touch = out + c->off_touch;
  for (int64_t p = 0; p < c->n_parts; p++) touch[p] = 0.0;
  int contact = 0;
  const int ncon = d->ncon;
  int pyramid = 0;
  if (!c->elliptic)
    for (int i = 0; i < ncon; i++) pyramid |= d->contact[i].dim > 1;
  for (int i = 0; i < ncon; i++) {
    const mjContact *con = d->contact + i;
    int g1 = con->geom1, g2 = con->geom2;
    if ((c->probe_hand_geom[g1] && c->handle_geom[g2]) || (c->probe_hand_geom[g2] && c->handle_geom[g1])) contact = 1;
    int h1 = c->touch_hand_geom[g1], h2 = c->touch_hand_geom[g2];
    if (h1 == h2) continue;
    double force;
    if (pyramid) {  /* HandTouch.vector_reference: mj_contactForce decodes the pyramid */
      mjtNum f6[6];
      mj_contactForce(m, d, i, f6);
      force = f6[0];
    } else {  /* the normal force is the contact's first constraint force */
      force = con->efc_address >= 0 ? d->efc_force[con->efc_address] : 0.0;
    }
    touch[c->part_of_geom[h1 ? g1 : g2]] += fabs(force);
  }
  /* grasp site to the handle box (RewardProbe.distance) */
  int64_t status = 0;
  const double *s = d->site_xpos + 3 * c->site;
  double distance = 0.0;
  /* Python's test: the sum of the nine numbers is finite */
  if (!isfinite(s[0] + s[1] + s[2] + lo[0] + lo[1] + lo[2] + hi[0] + hi[1] + hi[2])) {
    status |= OFS_DISTANCE;
  } else {
    double outside[3];
    for (int i = 0; i < 3; i++) {
      double a = lo[i] - s[i], b = s[i] - hi[i];
      a = a > b ? a : b;
      outside[i] = a > 0.0 ? a : 0.0;
    }
    distance = sqrt(dot(c, outside, outside, 3));
  }
  double *t = c->terms;
  t[0] = distance;
  t[1] = contact;
  t[2] = open_ratio;
  t[3] = others_range;
  t[4] = open_ratio > c->threshold;
  t[5] = others && others_range > c->moved_threshold;
  t[6] = opening / c->range_span;
  return status;
}

/* ---------------------------------------------------------------- the environment's step */

/* One control step of OpenDCore.step (lean): the action (delta: c->action -> c->native; absolute:
 * c->native as given), the task's action, the substeps, the NaN check, the observation vector and the
 * reward terms. Status bits say what the caller still has to do. */
int64_t ofs_env_step(ofs_ctx *c, int64_t delta, int64_t cameras, int64_t privileged) {
  if (delta) {
    if (delta_native(c)) return OFS_BAD_ACTION;
  } else {
    for (int64_t i = 0; i < 7 + c->n_fingers; i++)
      if (!isfinite(c->native[i])) return OFS_BAD_ACTION;
  }
  int64_t status = ofs_apply(c);
  if (status) return status;
  status = ofs_substeps(c, cameras);
  if (!status)
    for (int i = 0; i < c->m->nq; i++)
      if (!isfinite(c->d->qpos[i])) {
        status |= OFS_NAN;
        break;
      }
  if (c->d->time >= c->time_limit) status |= OFS_LAST;
  return status | ofs_fill(c, privileged, 0);
}
