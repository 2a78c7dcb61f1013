"""Friction regressors as plain ``nn.Module``s: MLP, full-attention transformer, Linformer.

Every model maps raw windows ``x`` (B, T=40, 36) — q [rad], qdot [rad/s], tau [N·m] per step, core joint
order — to a Gaussian over the friction coefficient: ``(mean, log_var)`` each (B,), in physical units
([-] and log [-]^2). With ``lower_quantile = q > 0`` the head has a third output, a lower-quantile estimate
``lower = mean - softplus(.) * y_std`` (never above the mean), trained with the pinball loss at level q
(:meth:`FrictionModel.predict` returns it; ``forward`` keeps returning ``(mean, log_var)``). Feature and
label normalisation statistics are buffers of the model, so a saved ``state_dict`` is self-contained.

Tokenisation for the transformers (paper, "Network Architecture", ViT-like):
* ``"joint"``: one token per joint per time step (T x 12 = 480 tokens of 3 features q, qdot, tau), with a
  learned temporal embedding (T, d) plus a learned spatial (joint) embedding (12, d);
* ``"step"``: one token per time step (T = 40 tokens of 36 features) with a learned temporal embedding.
Pooling is the mean over tokens or a learned CLS token. Options tried in the estimators' design study and
kept (not used by the shipped checkpoints, ``studies/notes/estimators/design.md``): ``window_norm`` (per-window
torque scale removed, :func:`window_features`) and ``kinematic_features`` (:func:`foot_kinematics`).
With ``filter_mu_input`` the raw windows carry 2 more features per step after the 36 (filter in the loop
0 / 1, the friction it assumed [-]; :func:`estimators.features.filter_channels`), step tokens and the mlp
only. Linformer projects keys and values along the sequence from n to ``linformer_k`` with learned (k, n)
matrices (Wang et al. 2020), one pair per layer.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import asdict, dataclass, field
from typing import TypeVar

import torch
import torch.nn.functional as F
from torch import nn

from estimators import legs
from estimators.features import N_CHANNELS, N_FEATURES, N_FILTER_FEATURES, N_JOINTS, WINDOW_STEPS
from taslel_bench.api import RobotDescription, leg_chain
from taslel_bench.interfaces import quad

VARIANTS = ("mlp", "attention", "linformer")
TOKENISATIONS = ("joint", "step", "foot")
WINDOW_NORMS = ("none", "tau", "tau_q")
POOLINGS = ("mean", "cls")
LOG_VAR_RANGE = (-12.0, 4.0)  # clamp of the normalised log-variance
T = TypeVar("T")


@dataclass
class ModelConfig:
    """Architecture hyper-parameters (one dataclass for every variant; unused fields are ignored)."""

    variant: str = "linformer"
    tokens: str = "joint"
    pooling: str = "mean"
    d_model: int = 32
    n_layers: int = 2
    n_heads: int = 2
    ff_mult: int = 2
    dropout: float = 0.0
    linformer_k: int = 32
    mlp_hidden: list[int] = field(default_factory=lambda: [256, 256])
    window_steps: int = WINDOW_STEPS
    use_tau: bool = True  # False: torque features are zeroed after normalisation (q, qdot only)
    lower_quantile: float = 0.0  # > 0: extra head for this quantile of mu given the window (pinball loss)
    window_norm: str = "none"  # per-window invariances applied before standardisation (window_features)
    # True: each step also gets the 4 feet's positions [m] and velocities [m/s] relative to the trunk, in
    # trunk axes (foot_kinematics, 24 features computed from q and qdot); step tokens and the MLP only
    kinematic_features: bool = False
    # True: the raw windows carry the 2 filter features per step (estimators.features.filter_channels: filter
    # in the loop, the filter's mu [-]) after the 36; step tokens and the mlp only
    filter_mu_input: bool = False
    # True: each step also gets 8 slip features from leg kinematics (slip_features: per foot, the horizontal
    # speed of the foot relative to its stance partner's, and its height above the lowest foot [m])
    slip_features: bool = False
    # True: one output per foot (B, 4), LEGS order, trained on the friction under each foot; tokens="foot"
    # always (one token per foot per step, shared weights, a leg embedding), the mlp with a 4-foot head
    per_foot: bool = False

    def validate(self) -> ModelConfig:
        for name, value, valid in (
            ("variant", self.variant, VARIANTS),
            ("tokens", self.tokens, TOKENISATIONS),
            ("pooling", self.pooling, POOLINGS),
            ("window_norm", self.window_norm, WINDOW_NORMS),
        ):
            if value not in valid:
                raise ValueError(f"unknown {name} {value!r}; valid choices: {', '.join(valid)}")
        if not 0.0 <= self.lower_quantile < 0.5:
            raise ValueError(f"lower_quantile must be in [0, 0.5), got {self.lower_quantile!r}")
        if self.kinematic_features and self.variant != "mlp" and self.tokens == "joint":
            raise ValueError("kinematic_features needs tokens='step' (or the mlp): foot features are per leg, "
                             "joint tokens carry (q, qdot, tau) of one joint")
        if self.filter_mu_input and self.variant != "mlp" and self.tokens == "joint":
            raise ValueError("filter_mu_input needs tokens='step' (or the mlp): joint tokens carry (q, qdot, tau) "
                             "of one joint")
        if self.tokens == "foot" and self.variant != "mlp":
            self.per_foot = True
        if self.per_foot and self.variant != "mlp" and self.tokens != "foot":
            raise ValueError("per_foot needs tokens='foot' (or the mlp)")
        if self.slip_features and self.variant != "mlp" and self.tokens == "joint":
            raise ValueError("slip_features needs tokens='step' or 'foot' (or the mlp)")
        if self.variant != "mlp" and self.d_model % self.n_heads:
            raise ValueError(f"d_model={self.d_model} is not divisible by n_heads={self.n_heads}")
        return self

    @property
    def n_outputs(self) -> int:
        """Head outputs per estimate: normalised mean, log-variance (and the lower-quantile offset)."""
        return 3 if self.lower_quantile > 0 else 2

    @property
    def n_estimates(self) -> int:
        """Estimates per window: 4 (one per foot) with ``per_foot``, else 1."""
        return quad.N_LEGS if self.per_foot else 1

    @property
    def n_raw(self) -> int:
        """Features per step of the raw windows the model takes (36, or 38 with ``filter_mu_input``)."""
        return N_FEATURES + (N_FILTER_FEATURES if self.filter_mu_input else 0)

    @property
    def n_inputs(self) -> int:
        """Features per step the encoder sees (36, plus 24 foot features with ``kinematic_features``, plus 2
        filter features with ``filter_mu_input``)."""
        return (self.n_raw + (N_KIN_FEATURES if self.kinematic_features else 0)
                + (N_SLIP_FEATURES if self.slip_features else 0))

    @property
    def n_tokens(self) -> int:
        """Sequence length seen by attention (CLS included)."""
        n = self.window_steps * {"joint": N_JOINTS, "step": 1, "foot": quad.N_LEGS}[self.tokens]
        return n + (1 if self.pooling == "cls" else 0)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


TAU_RMS_FLOOR = 1e-3  # [N·m] floor of the window RMS torque (a window of zero torque stays finite)


def window_features(x: torch.Tensor, mode: str) -> torch.Tensor:
    """Per-window invariances of raw windows (B, T, 36) -> (B, T, 36), before standardisation.

    * ``"none"``: unchanged (q [rad], qdot [rad/s], tau [N·m]).
    * ``"tau"``: the 12 torques divided by the window's RMS torque over all joints and steps, so tau becomes
      dimensionless. Friction bounds a *ratio* of forces (tangential / normal); a payload or a weaker motor
      scales every stance torque of a window together (tau = J^T f), which this removes. The ratio
      pattern across joints and time is kept.
    * ``"tau_q"``: as ``"tau"``, and each joint's q minus its window mean [rad] (the posture offset a load
      causes), keeping the motion within the window.
    """
    if mode == "none":
        return x
    if mode not in WINDOW_NORMS:
        raise ValueError(f"unknown window_norm {mode!r}; valid choices: {', '.join(WINDOW_NORMS)}")
    q, qd, tau = x[..., :12], x[..., 12:24], x[..., 24:]
    rms = tau.pow(2).mean(dim=(1, 2), keepdim=True).sqrt().clamp_min(TAU_RMS_FLOOR)
    if mode == "tau_q":
        q = q - q.mean(dim=1, keepdim=True)
    return torch.cat([q, qd, tau / rms], dim=-1)


N_KIN_FEATURES = 24  # foot positions (4 x 3) and velocities (4 x 3)


Prediction = tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]  # (mean, variance, lower quantile or None)


def foot_kinematics(x: torch.Tensor, robot: RobotDescription | None = None) -> torch.Tensor:
    """Raw windows (B, T, 36) -> (B, T, 24): ``[p_foot (4 x 3) [m], v_foot (4 x 3) [m/s]]``, legs FL, FR, RL,
    RR, foot-sphere centres relative to the trunk origin, in trunk axes; v_foot = J_leg(q) qdot (the foot's
    velocity relative to the trunk, not in the world). The chain of ``robot`` (None: the A1,
    :data:`estimators.legs.TRAINED_ROBOT`) through :func:`taslel_bench.robot.leg_chain.feet_and_velocities`.
    A stance foot that holds has v_foot = -(v_trunk + omega x p_foot); feet of one stance pair that disagree
    beyond the rotation term are slipping, whatever the payload or motor strength."""
    b, t, _ = x.shape
    columns = torch.tensor(legs.chain_table(robot).T, dtype=x.dtype, device=x.device)
    p, v = leg_chain.feet_and_velocities(columns, x[..., :12], x[..., 12:24], torch)
    return torch.cat([p.reshape(b, t, 12), v.reshape(b, t, 12)], dim=-1)


N_SLIP_FEATURES = 8  # per foot: speed relative to the stance partner [m/s], height above the lowest foot [m]
STANCE_PARTNER = (3, 2, 1, 0)  # trot pairs in LEGS order: FL-RR, FR-RL


def slip_features(x: torch.Tensor, robot: RobotDescription | None = None) -> torch.Tensor:
    """Raw windows (B, T, 36) -> (B, T, 8): a slip signal from leg kinematics alone (``[d (4) [m/s], h (4)
    [m]]``, LEGS order). ``d_i`` = |v_i - v_j|, horizontal (trunk x, y), of foot i's velocity relative to the
    trunk (:func:`foot_kinematics` on ``robot``'s chain, None: the A1) against its trot partner j's: two stance
    feet that hold both move at
    -(v_trunk + omega x p), so d_i is the rotation term |omega x (p_i - p_j)| (small in a trot) plus the
    slip of either foot. ``h_i`` = foot i's height above the lowest foot in trunk axes: near 0 for the stance
    pair, so the model can tell the stance pair's d (a slip) from a swing foot's. The trunk's angular rate
    (the IMU gyro) would remove the rotation term; the loop's Proprioception carries no IMU yet."""
    b, t, _ = x.shape
    kin = foot_kinematics(x, robot)
    p, v = kin[..., :12].reshape(b, t, 4, 3), kin[..., 12:].reshape(b, t, 4, 3)
    dv = v[..., :2] - v[:, :, list(STANCE_PARTNER), :2]
    d = dv.pow(2).sum(-1).add(1e-12).sqrt()
    h = p[..., 2] - p[..., 2].min(dim=-1, keepdim=True).values
    return torch.cat([d, h], dim=-1)


def foot_token_index(cfg: ModelConfig) -> torch.Tensor:
    """(4, n_leg) indices into the encoder's feature vector (:meth:`FrictionModel.features` layout) of each
    foot's token: its 3 joints' q, qdot, tau, its foot position and velocity (``kinematic_features``), its
    two slip features (``slip_features``) and the 2 filter features (``filter_mu_input``, shared)."""
    rows = []
    kin0 = N_FEATURES
    slip0 = kin0 + (N_KIN_FEATURES if cfg.kinematic_features else 0)
    filt0 = slip0 + (N_SLIP_FEATURES if cfg.slip_features else 0)
    for leg in range(quad.N_LEGS):
        j = [3 * leg + i for i in range(3)]
        idx = j + [12 + i for i in j] + [24 + i for i in j]
        if cfg.kinematic_features:
            idx += [kin0 + i for i in j] + [kin0 + 12 + i for i in j]
        if cfg.slip_features:
            idx += [slip0 + leg, slip0 + 4 + leg]
        if cfg.filter_mu_input:
            idx += [filt0, filt0 + 1]
        rows.append(idx)
    return torch.tensor(rows)


class Normaliser(nn.Module):
    """Per-feature standardisation of x and of the label; statistics are buffers (saved with the model)."""

    def __init__(self, n_features: int = N_FEATURES) -> None:
        super().__init__()
        self.register_buffer("x_mean", torch.zeros(n_features))
        self.register_buffer("x_std", torch.ones(n_features))
        self.register_buffer("y_mean", torch.tensor(0.0))
        self.register_buffer("y_std", torch.tensor(1.0))
        # added to the predicted log-variance: log of the variance scale fitted on validation data
        self.register_buffer("log_var_offset", torch.tensor(0.0))

    @torch.no_grad()
    def fit(self, x: torch.Tensor, y: torch.Tensor) -> None:
        """Set statistics from training windows (N, T, 36) and labels (N,); ``x`` as the encoder sees it
        (after :func:`window_features`, see :meth:`FrictionModel.fit_normaliser`)."""
        flat = x.reshape(-1, x.shape[-1]).double()
        self.x_mean.copy_(flat.mean(0).float())
        self.x_std.copy_(flat.std(0).clamp_min(1e-6).float())
        self.y_mean.copy_(y.double().mean().float())
        self.y_std.copy_(y.double().std().clamp_min(1e-6).float())


@torch.no_grad()
def calibrate_variance(model: FrictionModel | EnsembleModel, x: torch.Tensor, y: torch.Tensor,
                       batch: int = 512) -> float:
    """Scale the predicted variance so the Gaussian NLL on (x, y) is minimal (closed form:
    s = mean((y - mean)^2 / var)); stores log s in the model (a single model's ``norm.log_var_offset``, an
    ensemble's own ``log_var_offset``) and returns s (variance scale)."""
    model.eval()
    offset = model.log_var_offset if isinstance(model, EnsembleModel) else model.norm.log_var_offset
    offset.zero_()
    ratios = []
    for i in range(0, len(y), batch):
        mean, log_var = model(x[i : i + batch])
        ratios.append((y[i : i + batch] - mean) ** 2 * torch.exp(-log_var))
    s = float(torch.cat(ratios).mean())
    offset.fill_(math.log(max(s, 1e-6)))
    return s


class FrictionModel(nn.Module):
    """Base: normalise, ``encode`` to (B, 2) normalised (mean, log_var), de-normalise."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg.validate()
        self.norm = Normaliser(cfg.n_inputs)

    def encode(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    @torch.no_grad()
    def fit_normaliser(self, x: torch.Tensor, y: torch.Tensor, batch: int = 8192) -> None:
        """Standardisation statistics from raw training windows (N, T, 36) and labels (N,)."""
        feats = torch.cat([self.features(x[i : i + batch]) for i in range(0, len(x), batch)])
        self.norm.fit(feats, y)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Raw windows (B, T, n_raw) -> what is standardised and encoded (B, T, n_inputs):
        [proprioception (36, after :func:`window_features`), foot kinematics (24, optional), filter (2, optional)]."""
        prop = x[..., :N_FEATURES]
        parts = [window_features(prop, self.cfg.window_norm)]
        if self.cfg.kinematic_features:
            parts.append(foot_kinematics(prop))
        if self.cfg.slip_features:
            parts.append(slip_features(prop))
        if self.cfg.filter_mu_input:
            parts.append(x[..., N_FEATURES:])
        return torch.cat(parts, dim=-1) if len(parts) > 1 else parts[0]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x`` (B, T, 36) raw -> (mean [-], log_var [log -^2]) each (B,)."""
        mean, log_var, _ = self.predict(x)
        return mean, log_var

    def predict(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """``x`` (B, T, n_raw) raw -> (mean [-], log_var [log -^2], lower-quantile [-] or None) each (B,), or
        (B, 4) per foot (``per_foot``, LEGS order). The lower quantile is computed from the *detached* mean, so
        its loss never moves the mean."""
        return run_stages(self.predict_stages(x))

    def encode_stages(self, x: torch.Tensor) -> Generator[None, None, torch.Tensor]:
        """:meth:`encode` in slices (a generator that yields between them and returns the result); the
        default is one slice."""
        return self.encode(x)
        yield

    def predict_stages(self, x: torch.Tensor) -> Generator[None, None, Prediction]:
        """:meth:`predict` as a generator that yields between slices of the network (embedding, each
        attention / feed-forward half-block, each MLP layer) and returns predict's result: the in-loop
        estimator runs one slice per control tick (``inference="staged"``)."""
        if x.ndim != 3 or x.shape[-1] != self.cfg.n_raw or x.shape[1] != self.cfg.window_steps:
            hint = " (36 proprioception + 2 filter features, see estimators.features.with_filter_channels)" \
                if self.cfg.filter_mu_input else ""
            raise ValueError(
                f"expected windows (B, {self.cfg.window_steps}, {self.cfg.n_raw}){hint}, got {tuple(x.shape)}"
            )
        z = (self.features(x) - self.norm.x_mean) / self.norm.x_std
        if not self.cfg.use_tau:
            z = torch.cat([z[..., :24], torch.zeros_like(z[..., 24:N_FEATURES]), z[..., N_FEATURES:]], dim=-1)
        out = yield from self.encode_stages(z)  # (B, n_outputs), or (B, 4, n_outputs) per foot
        mean = out[..., 0] * self.norm.y_std + self.norm.y_mean
        log_var = out[..., 1].clamp(*LOG_VAR_RANGE) + 2.0 * torch.log(self.norm.y_std) + self.norm.log_var_offset
        lower = None
        if out.shape[-1] > 2:
            lower = mean.detach() - F.softplus(out[..., 2]) * self.norm.y_std
        return mean, log_var, lower


class MLPModel(FrictionModel):
    """Flattened window (T x 36) -> GELU MLP -> (mean, log_var)."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__(cfg)
        layers: list[nn.Module] = []
        width = cfg.window_steps * cfg.n_inputs
        for h in cfg.mlp_hidden:
            layers += [nn.Linear(width, h), nn.GELU(), nn.Dropout(cfg.dropout)]
            width = h
        layers.append(nn.Linear(width, cfg.n_outputs * cfg.n_estimates))
        self.net = nn.Sequential(*layers)

    def _shape(self, out: torch.Tensor) -> torch.Tensor:
        return out.reshape(out.shape[0], quad.N_LEGS, -1) if self.cfg.per_foot else out

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        return self._shape(self.net(x.flatten(1)))

    def encode_stages(self, x: torch.Tensor) -> Generator[None, None, torch.Tensor]:
        h = x.flatten(1)
        for i, layer in enumerate(self.net):
            if i and isinstance(layer, nn.Linear):
                yield
            h = layer(h)
        return self._shape(h)


class SelfAttention(nn.Module):
    """Multi-head self-attention; full, or Linformer with keys/values projected along the sequence."""

    def __init__(self, d: int, heads: int, n_tokens: int, linformer_k: int | None, dropout: float) -> None:
        super().__init__()
        self.heads, self.dropout = heads, dropout
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)
        self.proj_k = self.proj_v = None
        if linformer_k is not None:
            scale = 1.0 / math.sqrt(n_tokens)
            self.proj_k = nn.Parameter(torch.randn(linformer_k, n_tokens) * scale)  # (k, n)
            self.proj_v = nn.Parameter(torch.randn(linformer_k, n_tokens) * scale)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, d = x.shape
        q, k, v = self.qkv(x).chunk(3, dim=-1)
        if self.proj_k is not None:
            k = torch.einsum("kn,bnd->bkd", self.proj_k, k)
            v = torch.einsum("kn,bnd->bkd", self.proj_v, v)

        def heads(t: torch.Tensor) -> torch.Tensor:
            return t.reshape(b, t.shape[1], self.heads, d // self.heads).transpose(1, 2)

        p = self.dropout if self.training else 0.0
        y = F.scaled_dot_product_attention(heads(q), heads(k), heads(v), dropout_p=p)
        return self.out(y.transpose(1, 2).reshape(b, n, d))


class Block(nn.Module):
    """Pre-norm transformer block: x + Attn(LN(x)); x + FF(LN(x))."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        d = cfg.d_model
        k = cfg.linformer_k if cfg.variant == "linformer" else None
        self.ln1, self.ln2 = nn.LayerNorm(d), nn.LayerNorm(d)
        self.attn = SelfAttention(d, cfg.n_heads, cfg.n_tokens, k, cfg.dropout)
        self.ff = nn.Sequential(
            nn.Linear(d, cfg.ff_mult * d), nn.GELU(), nn.Dropout(cfg.dropout), nn.Linear(cfg.ff_mult * d, d)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.feed_forward(self.attention(x))

    def attention(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.attn(self.ln1(x))

    def feed_forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.ff(self.ln2(x))


class TransformerModel(FrictionModel):
    """ViT-like regressor: tokens + learned spatial/temporal embeddings -> blocks -> pool -> Gaussian head."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__(cfg)
        d, t = cfg.d_model, cfg.window_steps
        # (4, n_leg) feature indices of each foot's token (tokens="foot"; not saved: derived from the config)
        self.register_buffer("foot_index", foot_token_index(cfg) if cfg.tokens == "foot" else None, persistent=False)
        in_dim = {"joint": N_CHANNELS, "step": cfg.n_inputs, "foot": 0}[cfg.tokens]
        in_dim = in_dim or int(self.foot_index.shape[1])  # type: ignore[union-attr]
        self.embed = nn.Linear(in_dim, d)
        self.pos_time = nn.Parameter(torch.randn(t, 1, d) * 0.02)  # (T, 1, d)
        n_space = {"joint": N_JOINTS, "step": 1, "foot": quad.N_LEGS}[cfg.tokens]
        self.pos_space = nn.Parameter(torch.randn(1, n_space, d) * 0.02)  # (1, J, d)
        self.cls = nn.Parameter(torch.zeros(1, 1, d)) if cfg.pooling == "cls" else None
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.n_layers))
        self.ln = nn.LayerNorm(d)
        self.head = nn.Linear(d, cfg.n_outputs)

    def tokens(self, x: torch.Tensor) -> torch.Tensor:
        """(B, T, 36) normalised -> (B, n_tokens, d) with position embeddings (time-major order)."""
        b, t, _ = x.shape
        if self.cfg.tokens == "joint":
            x = x.reshape(b, t, N_CHANNELS, N_JOINTS).transpose(2, 3)  # (B, T, 12, 3)
        elif self.cfg.tokens == "foot":
            x = x[..., self.foot_index]  # (B, T, 4, n_leg)
        else:
            x = x.unsqueeze(2)  # (B, T, 1, 36)
        h = self.embed(x) + self.pos_time + self.pos_space
        h = h.reshape(b, -1, self.cfg.d_model)
        if self.cls is not None:
            h = torch.cat([self.cls.expand(b, -1, -1), h], dim=1)
        return h

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        h = self.tokens(x)
        for blk in self.blocks:
            h = blk(h)
        return self._head(h)

    def _head(self, h: torch.Tensor) -> torch.Tensor:
        """(B, n_tokens, d) -> (B, n_outputs), or per foot (B, 4, n_outputs): each foot's tokens pooled over
        time (its CLS output added, if any), one shared head."""
        h = self.ln(h)
        if self.cfg.tokens == "foot":
            cls = h[:, :1] if self.cls is not None else 0.0
            body = h[:, 1:] if self.cls is not None else h
            per_foot = body.reshape(h.shape[0], self.cfg.window_steps, quad.N_LEGS, -1).mean(1)  # (B, 4, d)
            return self.head(per_foot + cls)
        pooled = h[:, 0] if self.cls is not None else h.mean(1)
        return self.head(pooled)

    def encode_stages(self, x: torch.Tensor) -> Generator[None, None, torch.Tensor]:
        h = self.tokens(x)
        for blk in self.blocks:
            yield
            h = blk.attention(h)
            yield
            h = blk.feed_forward(h)
        return self._head(h)


class EnsembleModel(nn.Module):
    """A deep ensemble (Lakshminarayanan et al. 2017) of :class:`FrictionModel` members with one config,
    trained from different seeds. ``predict`` has the members' signature and units: the mean of the member
    means; the variance of the mixture, mean of the member variances plus the variance of the member means
    (so disagreement between members, which grows off the training distribution, widens sigma), times
    ``exp(log_var_offset)`` (fitted on validation data like a single model's, :func:`calibrate_variance`);
    the lower quantile, the ensemble mean minus the members' mean (mean - lower) gap."""

    def __init__(self, members: list[FrictionModel]) -> None:
        super().__init__()
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least 2 members, got {len(members)}")
        if any(m.cfg != members[0].cfg for m in members[1:]):
            raise ValueError("ensemble members must share one ModelConfig (they differ only in training seed)")
        self.cfg = members[0].cfg
        self.members = nn.ModuleList(members)
        self.register_buffer("log_var_offset", torch.tensor(0.0))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, log_var, _ = self.predict(x)
        return mean, log_var

    def predict(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        return run_stages(self.predict_stages(x))

    def predict_stages(self, x: torch.Tensor) -> Generator[None, None, Prediction]:
        """The members' slices one after the other (:meth:`FrictionModel.predict_stages`)."""
        outs = []
        for i, m in enumerate(self.members):
            if i:
                yield
            outs.append((yield from m.predict_stages(x)))
        means = torch.stack([o[0] for o in outs])  # (M, B)
        var = torch.stack([torch.exp(o[1]) for o in outs]).mean(0) + means.var(0, unbiased=False)
        mean = means.mean(0)
        log_var = torch.log(var.clamp_min(1e-12)) + self.log_var_offset
        lower = None
        if outs[0][2] is not None:
            gap = torch.stack([o[0] - o[2] for o in outs]).mean(0)  # type: ignore[operator]
            lower = mean - gap
        return mean, log_var, lower


def run_stages(gen: Generator[None, None, T]) -> T:
    """Run a ``*_stages`` generator to the end and return its result."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


def build_model(cfg: ModelConfig) -> FrictionModel:
    """Model for ``cfg.variant`` (mlp, attention, linformer)."""
    cfg.validate()
    return MLPModel(cfg) if cfg.variant == "mlp" else TransformerModel(cfg)


def parameter_count(model: nn.Module) -> int:
    """Trainable parameters (normalisation buffers excluded)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
