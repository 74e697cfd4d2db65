"""Linearization of the closed-loop diagram, modal analysis and the fast
linear frequency response.

The model is simulated with Drake's discrete SAP solver, so it is linearized
as the discrete map it is: x+ = A x + B u, y = C x + D u (period h), about
the static equilibrium of that same map (`simulation.static_equilibrium`):

* ``method="autodiff"``: Drake's `Linearize` on the AutoDiffXd-converted
  diagram, where every part supports it (sphere/half-space contact does,
  Drake's ellipsoid contact does not);
* ``method="fd"``: central finite differences of the discrete step and of
  the outputs (works for every contact model; step 1e-4 in each state,
  chosen above the ~1e-10 noise of the SAP solution and far below the
  geometric nonlinearity, so A agrees with AutoDiff to ~1e-10 where both
  work);
* ``method="auto"``: AutoDiff if Drake supports the diagram, else FD.

Eigenvalues z of A map to the continuous s = ln(z)/h, giving natural
frequencies and damping ratios.  These describe the simulated (discrete)
dynamics: SAP integrates contact and joint damping implicitly, which adds
~omega h / 2 of numerical damping (0.016 at 5 Hz with h = 1 ms).

The frequency response is evaluated at z = exp(j 2 pi f h) through the
eigen-decomposition (all 3 inputs x all outputs x 240 frequencies in a few
ms) and reported in the measured-data format (`FrfData`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..diagram import EhmDiagram
from ..systems.outputs import CHANNEL_NAMES, DOFS, SEGMENTS
from .formats import FrfData

INPUT_NAMES = ("seat_ax", "seat_ay", "seat_az")
OUTPUT_PORTS = ("channels", "seat_forces", "joint_torques", "his_torque")
FD_STEP = 1e-4
INPUT_FD_STEP = 1.0
ROTATIONAL = ("roll", "pitch", "yaw")
#: A rotation of 1 rad counts like a translation of this length when mode
#: shapes compare translations (m) and rotations (rad): a trunk-sized lever.
SHAPE_LENGTH_M = 0.3


class LinearizationError(RuntimeError):
    """The diagram could not be linearized (with the requested method)."""


@dataclass
class Mode:
    """One mode of the linearized closed loop."""

    index: int
    eigenvalue_z: complex  # discrete eigenvalue
    s: complex  # continuous equivalent ln(z)/h
    freq_hz: float  # undamped natural frequency |s|/2pi
    damping_ratio: float
    kind: str  # "oscillatory", "real", "integrator", "slip", "unstable"
    label: str
    shape: dict = field(default_factory=dict)  # channel -> (amplitude, phase_deg)
    dominant: str = ""
    state_share: dict = field(default_factory=dict)  # state group -> energy share
    #: Eigenvector over all states (complex; zero on the slip anchors).
    vector: np.ndarray | None = field(default=None, repr=False)

    @property
    def stable(self) -> bool:
        return abs(self.eigenvalue_z) < 1.0 + 1e-12 or self.kind == "slip"

    def to_dict(self) -> dict:
        return {
            "index": self.index,
            "freq_hz": self.freq_hz,
            "damping_ratio": self.damping_ratio,
            "label": self.label,
            "kind": self.kind,
            "stable": self.stable,
            "eigenvalue_s": [self.s.real, self.s.imag],
            "dominant": self.dominant,
            "shape": {k: {"amplitude": a, "phase_deg": p} for k, (a, p) in self.shape.items()},
            "state_share": self.state_share,
        }


@dataclass
class LinearModel:
    """x+ = A x + B u, y = C x + D u with period h (deviations from x0, y0)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    h: float
    state_names: list[str]
    output_names: list[str]
    x0: np.ndarray
    y0: np.ndarray
    state_groups: dict  # name -> slice of the state vector
    output_groups: dict  # name -> slice of the output vector
    method: str = "fd"
    input_names: tuple = INPUT_NAMES
    _eig: tuple | None = field(default=None, repr=False)

    # -- eigen-structure ---------------------------------------------------------------

    def _reduced(self) -> np.ndarray:
        """States that matter for the input-output map: all but the slip
        anchors, which are constant unless a restraint is at its limit."""
        keep = np.ones(len(self.state_names), bool)
        if "slip" in self.state_groups:
            keep[self.state_groups["slip"]] = False
        return np.flatnonzero(keep)

    def eig(self):
        """(eigenvalues, V, W = V^-1) of the reduced A."""
        if self._eig is None:
            k = self._reduced()
            lam, V = np.linalg.eig(self.A[np.ix_(k, k)])
            self._eig = (lam, V, np.linalg.inv(V), k)
        return self._eig[:3]

    def continuous_eigenvalues(self) -> np.ndarray:
        lam = self.eig()[0]
        return np.log(lam.astype(complex)) / self.h

    @property
    def is_stable(self) -> bool:
        return bool(np.all(np.abs(self.eig()[0]) < 1.0 + 1e-9))

    # -- frequency response ------------------------------------------------------------

    def frequency_response(self, freqs_hz, outputs: str | slice | None = None) -> np.ndarray:
        """H(z) at z = exp(j 2 pi f h): array (nf, ny, 3), output units per
        m/s^2 of seat acceleration."""
        lam, V, W = self.eig()
        k = self._eig[3]
        rows = (self.output_groups[outputs] if isinstance(outputs, str)
                else (outputs if outputs is not None else slice(None)))
        CV = self.C[rows][:, k] @ V
        WB = W @ self.B[k]
        z = np.exp(2j * np.pi * np.asarray(freqs_hz, float) * self.h)
        G = 1.0 / (z[:, None] - lam[None, :])
        return np.einsum("yk,fk,ku->fyu", CV, G, WB, optimize=True) + self.D[rows][None]

    def seat_displacement_per_acceleration(self, freqs_hz) -> np.ndarray:
        """D(z)/A(z) of the seat: the discrete double integration used by the
        simulation (v+ = v + h a, d+ = d + h v+): h^2 z / (z - 1)^2."""
        z = np.exp(2j * np.pi * np.asarray(freqs_hz, float) * self.h)
        return self.h**2 * z / (z - 1.0) ** 2

    def transmissibility_array(self, freqs_hz=None, directions="xyz") -> np.ndarray:
        """Complex transmissibility (nf, 30 channels, len(directions)):
        absolute translations in m/m, rotations in deg/m."""
        f = default_frequencies() if freqs_hz is None else np.asarray(freqs_hz, float)
        cols = ["xyz".index(d) for d in directions]
        H = self.frequency_response(f, "channels")[:, :, cols]  # per m/s^2
        T = H / self.seat_displacement_per_acceleration(f)[:, None, None]
        for j, d in enumerate(directions):
            T[:, CHANNEL_NAMES.index(f"pelvis_{d}")::6, j] += 1.0  # absolute motion
        T[:, _ROT_MASK, :] *= 180.0 / np.pi
        return T

    def transmissibility(self, freqs_hz=None, directions="xyz", coherence: float = 1.0) -> FrfData:
        """Seat-to-body transmissibility in the measured-data format: gain
        m/m (translations, absolute motion) or deg/m (rotations)."""
        f = default_frequencies() if freqs_hz is None else np.asarray(freqs_hz, float)
        return frf_from_array(self.transmissibility_array(f, directions), f, directions,
                              coherence)

    def apparent_mass(self, freqs_hz=None, directions="xz"):
        """Normalized apparent mass of the pan: {direction: (f, modulus, phase_deg)}."""
        f = default_frequencies() if freqs_hz is None else np.asarray(freqs_hz, float)
        H = self.frequency_response(f, "seat_forces")
        names = [self.output_names[i] for i in range(*self.output_groups["seat_forces"]
                                                        .indices(len(self.output_names)))]
        pan_z = self.y0[self.output_groups["seat_forces"]][names.index("pan_fz")]
        m_static = pan_z / 9.81
        out = {}
        for d in directions:
            M = H[:, names.index(f"pan_f{d}"), "xyz".index(d)]
            out[d] = (f, np.abs(M) / m_static, np.degrees(np.angle(M)))
        return out

    # -- modes -------------------------------------------------------------------------

    def modes(self, include_slip: bool = True) -> list[Mode]:
        """All modes, one per complex-conjugate pair, sorted by frequency."""
        lam, V, _ = self.eig()
        k = self._eig[3]
        names = [self.state_names[i] for i in k]
        groups = _groups_of(names)
        if "channels" in self.output_groups:
            C_ch = self.C[self.output_groups["channels"]][:, k]
        else:  # a generic diagram: shapes in its positions
            C_ch = None
        out, seen = [], set()
        for i in np.argsort(np.abs(np.log(lam.astype(complex)))):
            if i in seen:
                continue
            if abs(lam[i].imag) > 1e-12:  # skip its conjugate
                j = int(np.argmin(np.abs(lam - lam[i].conj()) + (np.arange(len(lam)) == i)))
                seen.add(j)
            seen.add(i)
            mode = self._make_mode(len(out), lam[i], V[:, i], groups, C_ch)
            full = np.zeros(len(self.state_names), complex)
            full[k] = V[:, i]
            mode.vector = full
            out.append(mode)
        if include_slip and "slip" in self.state_groups:
            s = self.state_groups["slip"]
            for n in self.state_names[s]:
                out.append(Mode(len(out), 1.0 + 0j, 0j, 0.0, 0.0, "slip",
                                f"slip anchor {n[5:]} (static; moves only at the force "
                                "limit; uncontrollable)", {}, n,
                                {"slip": 1.0}))
        out.sort(key=lambda m: (m.kind == "slip", m.freq_hz))
        for i, m in enumerate(out):
            m.index = i
        return out

    def _make_mode(self, index, z, v, groups, C_ch) -> Mode:
        s = complex(np.log(complex(z)) / self.h)
        wn = abs(s)
        zeta = -s.real / wn if wn > 0 else 0.0
        # Energy share of the state groups in the eigenvector.
        mag = np.abs(v) ** 2
        share = {g: float(mag[idx].sum() / mag.sum()) for g, idx in groups.items()}
        if abs(z) > 1.0 + 1e-9:
            kind = "unstable"
        elif abs(s.imag) < 1e-3 * wn:
            kind = "integrator" if share.get("pid", 0) > 0.5 else "real"
        else:
            kind = "oscillatory"
        if C_ch is None:
            q = groups.get("q", np.arange(len(v)))
            amp = np.abs(v[q])
            shape = {self.state_names[self._eig[3][i]]: (float(a / amp.max()), 0.0)
                     for i, a in zip(q, amp, strict=True)}
            dominant = max(shape, key=lambda n: shape[n][0])
            return Mode(index, complex(z), s, wn / (2 * math.pi), float(zeta), kind,
                        f"{kind}: {dominant}", shape, dominant, share)
        y = C_ch @ v
        scale = np.array([SHAPE_LENGTH_M if n.rsplit("_", 1)[-1] in ROTATIONAL else 1.0
                          for n in CHANNEL_NAMES])
        ys = y * scale
        amax = np.max(np.abs(ys)) if np.max(np.abs(ys)) > 0 else 1.0
        ref = ys[np.argmax(np.abs(ys))]
        rot = np.conj(ref) / abs(ref) if abs(ref) > 0 else 1.0
        shape = {n: (float(abs(ys[c]) / amax), float(np.degrees(np.angle(ys[c] * rot))))
                 for c, n in enumerate(CHANNEL_NAMES)}
        dominant = CHANNEL_NAMES[int(np.argmax(np.abs(ys)))]
        label = _describe(kind, shape, dominant, share, s)
        return Mode(index, complex(z), s, wn / (2 * math.pi), float(zeta), kind, label,
                    shape, dominant, share)

    def position_shape(self, mode: Mode) -> np.ndarray:
        """The mode's complex shape in the plant positions q, scaled so the
        largest body-channel motion (rotations x 0.3 m) is 1."""
        q = self.state_groups["q"]
        v = mode.vector
        if "channels" in self.output_groups:
            y = self.C[self.output_groups["channels"]] @ v
            scale = np.array([SHAPE_LENGTH_M if n.rsplit("_", 1)[-1] in ROTATIONAL else 1.0
                              for n in CHANNEL_NAMES])
            ref = (y * scale)[np.argmax(np.abs(y * scale))]
        else:
            ref = v[q][np.argmax(np.abs(v[q]))]
        return v[q] / ref

    def participation(self, direction: str, channel: str, freq_hz: float, top: int = 3):
        """Modes dominating the transmissibility of `channel` at `freq_hz`
        for seat excitation in `direction`: [(mode, share)], share of the
        sum of the modal terms' moduli."""
        lam, V, W = self.eig()
        k = self._eig[3]
        c = self.output_groups["channels"].start + CHANNEL_NAMES.index(channel)
        j = "xyz".index(direction)
        z = np.exp(2j * np.pi * freq_hz * self.h)
        terms = (self.C[c, k] @ V) * (W @ self.B[k, j]) / (z - lam)
        modes = self.modes(include_slip=False)
        contrib = []
        for m in modes:
            idx = np.flatnonzero(np.abs(lam - m.eigenvalue_z) < 1e-9 * max(1, abs(m.eigenvalue_z)))
            idx = np.concatenate([idx, np.flatnonzero(
                np.abs(lam - np.conj(m.eigenvalue_z)) < 1e-9)]) if m.s.imag else idx
            contrib.append(abs(terms[np.unique(idx)].sum()))
        contrib = np.array(contrib)
        total = contrib.sum() if contrib.sum() > 0 else 1.0
        order = np.argsort(contrib)[::-1][:top]
        return [(modes[i], float(contrib[i] / total)) for i in order]


_ROT_MASK = np.array([n.rsplit("_", 1)[-1] in ROTATIONAL for n in CHANNEL_NAMES])


def frf_from_array(T: np.ndarray, freqs, directions: str, coherence: float = 1.0) -> FrfData:
    """FrfData rows (direction, channel, frequency order) from a complex
    transmissibility array (nf, 30 channels, len(directions))."""
    f = np.asarray(freqs, float)
    nf, nc, nd = T.shape
    seg = np.array([_split(n)[0] for n in CHANNEL_NAMES])
    dof = np.array([_split(n)[1] for n in CHANNEL_NAMES])
    Tt = T.transpose(2, 1, 0).reshape(-1)
    return FrfData(
        direction=np.repeat(np.array(list(directions)), nc * nf),
        segment=np.tile(np.repeat(seg, nf), nd),
        dof=np.tile(np.repeat(dof, nf), nd),
        freq_hz=np.tile(f, nc * nd),
        gain=np.abs(Tt), phase_deg=np.degrees(np.angle(Tt)),
        coherence=np.full(Tt.size, coherence))


def default_frequencies(n: int = 240, f_max: float = 12.0) -> np.ndarray:
    """240 frequencies from 0.05 to 12 Hz (the analysis band)."""
    return np.linspace(f_max / n, f_max, n)


def _groups_of(names: list[str]) -> dict:
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        groups.setdefault(n.split(":", 1)[0], []).append(i)
    return {g: np.array(ix) for g, ix in groups.items()}


_DOF_WORDS = {"x": "fore-aft", "y": "lateral", "z": "vertical", "roll": "roll",
              "pitch": "pitch", "yaw": "yaw"}


def _describe(kind, shape, dominant, share, s) -> str:
    if kind == "integrator":
        return f"PID integrator (time constant {-1 / s.real:.2f} s)"
    seg, dof = _split(dominant)
    if seg.startswith("knee"):
        other = ("knee_r" if seg == "knee_l" else "knee_l") + "_" + dof
        a, p = shape[dominant]
        b, q = shape[other]
        if abs(a - b) < 0.05 * a:  # both knees alike: say how they move together
            same = abs(((p - q + 180) % 360) - 180) < 90
            seg = "knees " + ("in phase" if same else "opposed")
    # Second strongest body motion, if comparable.
    ranked = sorted(shape.items(), key=lambda kv: -kv[1][0])
    desc = f"{seg} {_DOF_WORDS[dof]}"
    for name, (a, _) in ranked[1:4]:
        s2, d2 = _split(name)
        if a > 0.6 and d2 != dof and not (seg.startswith("knees") and s2.startswith("knee")):
            desc += f" + {s2} {_DOF_WORDS[d2]}"
            break
    plane = "sagittal" if dof in ("x", "z", "pitch") else "lateral"
    if kind == "unstable":
        return f"UNSTABLE: {desc} ({plane})"
    if kind == "real":
        return f"overdamped: {desc} ({plane})"
    return f"{desc} ({plane})"


def _split(name: str) -> tuple[str, str]:
    for seg in SEGMENTS:
        if name.startswith(seg + "_") and name[len(seg) + 1:] in DOFS:
            return seg, name[len(seg) + 1:]
    raise ValueError(name)


# ---------------------------------------------------------------------------
# Linearization
# ---------------------------------------------------------------------------


def _state_names(model: EhmDiagram, smap) -> list[str]:
    plant = model.plant
    names = [""] * smap.size
    qn = [f"q:{n}" for n in plant.GetPositionNames(add_model_instance_prefix=False)]
    vn = [f"v:{n}" for n in plant.GetVelocityNames(add_model_instance_prefix=False)]
    names[smap.slice("plant")] = qn + vn
    if "joint_pid" in smap._index:
        names[smap.slice("joint_pid")] = [f"pid:{n}" for n in model.hp.layout.names]
    if "shear_restraints" in smap._index:
        pts = model.systems["shear_restraints"].points
        names[smap.slice("shear_restraints")] = [
            f"slip:{p.name}_{'xyz'[int(np.argmax(np.abs(a)))]}" for p in pts for a in p.axes]
    return names


def _output_names(model: EhmDiagram, ports) -> list[str]:
    from ..diagram import SEAT_FORCE_NAMES

    names = []
    for p in ports:
        if p == "channels":
            names += list(CHANNEL_NAMES)
        elif p == "seat_forces":
            names += list(SEAT_FORCE_NAMES)
        elif p == "joint_torques":
            names += [f"torque:{n}" for n in model.hp.layout.names]
        elif p == "his_torque":
            names += ["his_tx", "his_ty", "his_tz"]
        elif p == "softening_deformation":
            names += [f"softening:{n}" for n in model.systems["body_softening"].elements.names]
    return names


def linearize(model: EhmDiagram, root_context=None, method: str = "auto",
              fd_step: float = FD_STEP, outputs=None, central: bool = True) -> LinearModel:
    """Linearize the seated-human `model` (built without a signal) about the
    static equilibrium in `root_context` (computed when None)."""
    from ..simulation import StateMap, static_equilibrium

    if model.signal is not None:
        raise ValueError("linearize needs a diagram built without a signal (exported seat inputs)")
    if root_context is None:
        root_context, smap = static_equilibrium(model)
    else:
        smap = StateMap(model)
    model.diagram.GetInputPort("seat_displacement").FixValue(root_context, np.zeros(3))
    ports = [p for p in (outputs or OUTPUT_PORTS) if model.diagram.HasOutputPort(p)]
    return linearize_system(model.diagram, root_context, ports,
                            model.params.simulation.time_step_s, method, fd_step,
                            _state_names(model, smap), _output_names(model, ports), central)


def linearize_system(diagram, root_context, output_ports, h: float, method: str = "auto",
                     fd_step: float = FD_STEP, state_names=None, output_names=None,
                     central: bool = True) -> LinearModel:
    """Linearize any discrete Diagram (single period h) about the state in
    `root_context`, from its input port ``seat_acceleration`` (3) to the
    named output ports.  Other input ports must be fixed in the context."""
    from ..simulation import StateMap

    if method not in ("auto", "fd", "autodiff"):
        raise ValueError(f"method must be 'auto', 'fd' or 'autodiff', got {method!r}")
    smap = StateMap(diagram)
    x0 = smap.get(root_context)
    a_port = diagram.GetInputPort("seat_acceleration")
    a_port.FixValue(root_context, np.zeros(3))
    y0 = np.concatenate([diagram.GetOutputPort(p).Eval(root_context) for p in output_ports])
    used = None
    if method in ("auto", "autodiff"):
        try:
            A, B, C, D = _linearize_autodiff(diagram, root_context, output_ports)
            used = "autodiff"
        except (RuntimeError, SystemExit, TypeError, ValueError) as e:
            # Drake reports unsupported scalar conversion or geometry queries
            # (e.g. ellipsoid contact) as RuntimeError, some as SystemExit.
            if method == "autodiff":
                raise LinearizationError(f"AutoDiff linearization not possible: {e}") from None
    if used is None:
        # A restraint's slip anchor moves only at its force limit: the
        # input-output map and the modes leave the anchors out
        # (`LinearModel._reduced`), so their columns are not evaluated.
        held = [i for i, n in enumerate(state_names or ()) if n.startswith("slip:")]
        A, B, C, D = _linearize_fd(diagram, root_context, smap, output_ports, fd_step, central,
                                   held=held)
        used = "fd"
        smap.set(root_context, x0)
        a_port.FixValue(root_context, np.zeros(3))
    sizes = [diagram.GetOutputPort(p).size() for p in output_ports]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    out_groups = {p: slice(int(offsets[i]), int(offsets[i + 1]))
                  for i, p in enumerate(output_ports)}
    names = state_names or [f"x:{i}" for i in range(len(x0))]
    out_names = output_names or [f"{p}:{i}" for p, n in zip(output_ports, sizes, strict=True)
                                 for i in range(n)]
    state_groups = {}
    for g in ("q", "v", "pid", "slip"):
        idx = [i for i, n in enumerate(names) if n.startswith(g + ":")]
        if idx:
            state_groups[g] = slice(idx[0], idx[-1] + 1)
    return LinearModel(A, B, C, D, h, names, out_names, x0, y0, state_groups, out_groups, used)


def _linearize_fd(diagram, ctx, smap, ports, eps, central=True, inputs=None, held=()):
    """Central (or forward: half the cost, O(eps) error) differences.

    `inputs`: [(input port name, FD step)] to differentiate with respect to
    (default: the seat acceleration, step `INPUT_FD_STEP`); other input
    ports keep their fixed values.  `held`: state indices whose columns are
    not evaluated but set to a held state (A: the unit column, C: 0), for
    states the caller leaves out.  Returns A, B (inputs stacked), C, D."""
    inputs = inputs or [("seat_acceleration", INPUT_FD_STEP)]
    in_ports = [diagram.GetInputPort(name) for name, _ in inputs]
    u0s = [p.Eval(ctx) for p in in_ports]
    sizes = [len(u) for u in u0s]
    x0 = smap.get(ctx)
    n = len(x0)
    m = sum(sizes)
    u0 = np.concatenate(u0s)
    splits = np.cumsum(sizes)[:-1]

    def evaluate(x, u):
        smap.set(ctx, x)
        for port, part in zip(in_ports, np.split(u, splits), strict=True):
            port.FixValue(ctx, part)
        return smap.step(ctx), np.concatenate([diagram.GetOutputPort(p).Eval(ctx) for p in ports])

    cols_x, cols_y = [], []
    ny = sum(diagram.GetOutputPort(p).size() for p in ports)
    if not central:
        xc, yc = evaluate(x0, u0)
    # The seat input is perturbed by 1 m/s^2: its effect on one step (h * 1
    # m/s) must stand well above SAP's solution tolerance (~1e-8 m/s), and
    # the model is linear in it (inertial load) anyway.
    steps = np.r_[np.full(n, eps), np.repeat([step for _, step in inputs], sizes)]
    held = set(held)
    for j in range(n + m):
        if j in held:
            cols_x.append(np.eye(n)[j])
            cols_y.append(np.zeros(ny))
            continue
        ep = np.zeros(n + m)
        ep[j] = steps[j]
        e = steps[j]
        xp, yp = evaluate(x0 + ep[:n], u0 + ep[n:])
        if central:
            xm, ym = evaluate(x0 - ep[:n], u0 - ep[n:])
            cols_x.append((xp - xm) / (2 * e))
            cols_y.append((yp - ym) / (2 * e))
        else:
            cols_x.append((xp - xc) / e)
            cols_y.append((yp - yc) / e)
    evaluate(x0, u0)  # leave the context as found
    J = np.array(cols_x).T
    K = np.array(cols_y).T
    return J[:, :n], J[:, n:], K[:, :n], K[:, n:]


def _linearize_autodiff(diagram, ctx, ports):
    from pydrake.systems.primitives import Linearize

    A = B = None
    Cs, Ds = [], []
    for p in ports:
        lin = Linearize(diagram, ctx,
                        input_port_index=diagram.GetInputPort("seat_acceleration").get_index(),
                        output_port_index=diagram.GetOutputPort(p).get_index(),
                        equilibrium_check_tolerance=1e-6)
        A, B = lin.A(), lin.B()
        Cs.append(lin.C())
        Ds.append(lin.D())
    return A, B, np.vstack(Cs), np.vstack(Ds)
