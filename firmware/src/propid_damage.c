/*
 * Propeller damage detector (see propid_damage.h and docs/damage.md).
 *
 * Each gyro update leaves three sequential scalar innovations nu_a with
 * variances S_a; for an honest filter z_a = nu_a / sqrt(S_a) are independent
 * N(0, 1). A sudden loss of a fraction delta of rotor i's kf and km removes the
 * torque delta * u_i (a_i kf_rel_i + d_i km_rel_i) (J^-1 scaled, docs/math.md
 * section 1), so the next innovations move by -delta * g_i in the direction
 *     g_i,a = dt u_i (a_i,a kf_rel_i + d_i,a km_rel_i) / sqrt(S_a)
 * (and keep growing while the filter's rate absorbs the missing torque).
 * Rotor i's test statistic is the projection s_i = -(g_i . z) / |g_i|, N(0, 1)
 * on a healthy vehicle, positive mean after a loss on rotor i; it is
 * standardised by running moments (and, for correlated model error, by the
 * prediction error of an AR(1) fit) and a one-sided CUSUM on it,
 * C_i = max(0, C_i + x_i - k), alarms at C_i > h.
 */
#include "propid/propid_damage.h"

#include <math.h>
#include <string.h>

#include "propid_internal.h"

#define PROPID_DAMAGE_BISECTION_STEPS 60
#define PROPID_DAMAGE_H_MAX 200.0f
/* Siegmund's correction of the threshold for the overshoot of Gaussian increments. */
#define PROPID_DAMAGE_SIEGMUND 1.166f
/* A detection needs at least this many samples of evidence: increments are
 * clipped at drift + threshold / PROPID_DAMAGE_MIN_SAMPLES. */
#define PROPID_DAMAGE_MIN_SAMPLES 3.0f
/* Clip (in running sigmas) of the values that update the running mean/variance. */
#define PROPID_DAMAGE_CLIP 3.0f
/* Floor of the running variances with the fixed design (an honest filter
 * gives 1); the derived design floors them at the gyro noise's share. */
#define PROPID_DAMAGE_VAR_FLOOR 0.25f
/* Largest lag-1 correlation the whitening uses: the prediction error keeps at
 * least sqrt(1 - 0.95^2) = 31 % of the projection's own variance. */
#define PROPID_DAMAGE_RHO_MAX 0.95f

void propid_damage_config_default(propid_damage_config_t *config)
{
    if (config == NULL) {
        return;
    }
    config->false_alarms_per_hour = 1.0e-3f;
    config->design_shift_sigma = 8.0f;
    config->design_loss_fraction = 0.0f;
    config->hold_s = 0.5f;
    config->adapt_time_s = 0.5f;
}

/* An honest filter's moments: centred, unit variance, white. */
static void reset_moments(propid_damage_t *detector, uint8_t rotor)
{
    detector->mean[rotor] = 0.0f;
    detector->var[rotor] = 1.0f;
    detector->cov1[rotor] = 0.0f;
    detector->residual_var[rotor] = 1.0f;
    detector->previous[rotor] = 0.0f;
    detector->loss_shift[rotor] = 0.0f;
    detector->offset[rotor] = 0.0f;
    detector->offset_last[rotor] = 0.0f;
}

static float clip_symmetric(float value, float bound)
{
    return value > bound ? bound : value < -bound ? -bound : value;
}

/* In-control average run length of a CUSUM with drift k and threshold h. */
static float cusum_arl(float drift, float threshold)
{
    const float x = 2.0f * drift * (threshold + PROPID_DAMAGE_SIEGMUND);
    return (expf(x) - 1.0f - x) / (2.0f * drift * drift);
}

float propid_damage_threshold(float drift, float arl_samples)
{
    if (!(drift > 0.0f) || !(arl_samples > 1.0f) || !isfinite(drift) || !isfinite(arl_samples)) {
        return -1.0f;
    }
    float low = 0.0f;
    float high = PROPID_DAMAGE_H_MAX;
    if (!(cusum_arl(drift, high) > arl_samples)) {
        return -1.0f;
    }
    for (int i = 0; i < PROPID_DAMAGE_BISECTION_STEPS; ++i) {
        const float mid = 0.5f * (low + high);
        if (cusum_arl(drift, mid) < arl_samples) {
            low = mid;
        } else {
            high = mid;
        }
    }
    return high;
}

propid_status_t propid_damage_init(propid_damage_t *detector, const propid_damage_config_t *config,
                                   const propid_filter_t *filter)
{
    if (detector == NULL || config == NULL || filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (filter->magic != PROPID_MAGIC) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    const float rate_hz = filter->config.gyro_sample_rate_hz;
    const uint8_t rotor_count = filter->config.rotor_count;
    if (!(config->false_alarms_per_hour > 0.0f) || !isfinite(config->false_alarms_per_hour) ||
        !(config->design_shift_sigma > 0.0f) || !(config->design_shift_sigma < 50.0f) ||
        !(config->design_loss_fraction >= 0.0f) || !(config->design_loss_fraction < 1.0f) ||
        !(config->hold_s >= 0.0f) || !(config->hold_s < 60.0f) || !(rate_hz > 0.0f) ||
        !(config->adapt_time_s > 0.0f) || !(config->adapt_time_s < 600.0f) ||
        rotor_count == 0u || rotor_count > PROPID_MAX_ROTORS) {
        return PROPID_ERR_CONFIG;
    }
    /* The bank alarms falsely when any of its rotor_count tests does: each test
     * gets rotor_count times the bank's average run length (union bound). */
    const float samples_per_hour = 3600.0f * rate_hz;
    const float arl = (float)rotor_count * samples_per_hour / config->false_alarms_per_hour;
    const float drift = 0.5f * config->design_shift_sigma;
    const float threshold = propid_damage_threshold(drift, arl);
    if (!(threshold > 0.0f)) {
        return PROPID_ERR_CONFIG;
    }
    memset(detector, 0, sizeof(*detector));
    detector->config = *config;
    detector->drift = drift;
    detector->clip = drift + threshold / PROPID_DAMAGE_MIN_SAMPLES;
    detector->threshold = threshold;
    detector->arl_samples = arl;
    detector->rotor_count = rotor_count;
    detector->last_rotor = -1;
    detector->reanchors_seen = filter->counters.gate_reopened;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        reset_moments(detector, i);
        detector->rotor_drift[i] = drift;
        detector->rotor_threshold[i] = threshold;
        detector->rotor_clip[i] = detector->clip;
    }
    return PROPID_OK;
}

/* At arming, each rotor's CUSUM is tuned for the smallest loss it must catch
 * (docs/damage.md): a loss delta moves the projection by delta |g_i| on its
 * first sample (more later, while the rate absorbs the missing torque), in
 * running sigmas delta |g_i| / sd_i; the CUSUM's reference value for a shift mu
 * is mu / 2, and h is solved for that k from the same average run length, so
 * the derived false-alarm rate holds whatever k is. Where the shift cannot be
 * measured (no signature yet, or a k whose h is out of range) the configured
 * design shift stays. */
static void derive_rotor_design(propid_damage_t *detector)
{
    const float loss = detector->config.design_loss_fraction;
    for (uint8_t i = 0; i < detector->rotor_count; ++i) {
        const float k = 0.5f * loss * detector->loss_shift[i];
        float h = -1.0f;
        if (k > 0.0f && k < 0.5f * 50.0f) {
            h = propid_damage_threshold(k, detector->arl_samples);
        }
        if (h > 0.0f) {
            detector->rotor_drift[i] = k;
            detector->rotor_threshold[i] = h;
            detector->rotor_clip[i] = k + h / PROPID_DAMAGE_MIN_SAMPLES;
        } else {
            detector->rotor_drift[i] = detector->drift;
            detector->rotor_threshold[i] = detector->threshold;
            detector->rotor_clip[i] = detector->clip;
        }
    }
    detector->design_set = 1u;
}

/* The rotor's kf and km variance back to the prior, their correlations
 * cleared; the estimates stay where they are and re-converge. The body rates
 * are re-opened too: between the loss and its detection the unexplained
 * torque moved them (and the gate may have held the gyro off), and a rate
 * error left in place would be read as a larger loss. */
static void reopen_rotor(propid_filter_t *filter, uint8_t rotor)
{
    for (uint8_t a = 0; a < PROPID_RATE_STATES; ++a) {
        propid_cov_reset_state(&filter->derived, &filter->core, a);
        /* The unexplained torque moved the rate by about the innovation: the
         * re-opened rate variance covers it, so the next gyro samples correct
         * the rate instead of being read as a larger loss. */
        const float nu = filter->core.innovation[a];
        filter->core.cov[propid_cov_index(a, a)] += nu * nu;
        filter->core.gated_run[a] = 0u;
    }
    propid_cov_reset_rotor(&filter->derived, &filter->config, &filter->core, rotor, 0);
    filter->core.health |= PROPID_HEALTH_ROTOR_DAMAGE;
}

propid_status_t propid_damage_set_landed(propid_damage_t *detector, bool landed)
{
    if (detector == NULL) {
        return PROPID_ERR_NULL;
    }
    if (detector->rotor_count == 0u || detector->rotor_count > PROPID_MAX_ROTORS) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    detector->landed = landed;
    return PROPID_OK;
}

/* The bank from scratch: unarmed, statistics at zero, an honest filter's
 * moments; the rotors' design is derived again when it arms. */
static void restart_bank(propid_damage_t *detector)
{
    detector->armed_s = 0.0f;
    detector->design_set = 0u;
    for (uint8_t i = 0; i < detector->rotor_count; ++i) {
        detector->statistic[i] = 0.0f;
        reset_moments(detector, i);
    }
}

propid_status_t propid_damage_step(propid_damage_t *detector, propid_filter_t *filter,
                                   int8_t *detected_rotor)
{
    if (detector == NULL || filter == NULL || detected_rotor == NULL) {
        return PROPID_ERR_NULL;
    }
    *detected_rotor = -1;
    if (filter->magic != PROPID_MAGIC) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    if (filter->config.rotor_count != detector->rotor_count) {
        return PROPID_ERR_ROTOR_COUNT;
    }
    const propid_core_t *core = &filter->core;
    const uint64_t now = core->time_us;
    if (!detector->has_time || now <= detector->last_time_us) {
        detector->has_time = 1u;
        detector->last_time_us = now;
        return PROPID_OK;
    }
    const float dt = (float)(uint32_t)(now - detector->last_time_us) * 1.0e-6f;
    detector->last_time_us = now;
    if (detector->landed) {
        /* On the ground: no test, and nothing of the contact learnt; the
         * re-anchor count is followed so take-off starts from a clean slate. */
        detector->reanchors_seen = filter->counters.gate_reopened;
        restart_bank(detector);
        return PROPID_OK;
    }
    const int holding = now < detector->hold_until_us;

    /* Normalised innovations z_a and 1/sqrt(S_a) from the stored innovation and
     * its test ratio nu^2 / (gate^2 S) (inv_gate_sq is 1 with the gate off). */
    float z[3];
    float inv_sd[3];
    for (uint8_t a = 0; a < 3u; ++a) {
        const float nu = core->innovation[a];
        const float ratio = core->innovation_test_ratio[a] / filter->derived.inv_gate_sq;
        if (!(ratio > 0.0f) || !isfinite(ratio) || nu == 0.0f) {
            return PROPID_OK; /* no update on this axis: nothing to test */
        }
        const float magnitude = sqrtf(ratio);
        z[a] = nu > 0.0f ? magnitude : -magnitude;
        inv_sd[a] = magnitude / fabsf(nu);
    }

    /* Axes the filter re-anchored on this sample (propid_gyro.c: after
     * gate_max_consecutive gated samples in a row the rate is set on the gyro):
     * the re-anchor count moved, and the axis' innovation is outside the gate
     * with its gated run back at zero. The stored innovation is the one before
     * the re-anchor; from the next sample on that axis' innovation has lost
     * it, a step the filter made itself. */
    uint8_t reanchored[3] = {0u, 0u, 0u};
    const uint32_t reanchors = filter->counters.gate_reopened;
    if (reanchors != detector->reanchors_seen && filter->derived.gate_sq > 0.0f) {
        detector->reanchors_seen = reanchors;
        for (uint8_t a = 0; a < 3u; ++a) {
            reanchored[a] = (uint8_t)(core->innovation_test_ratio[a] > 1.0f && core->gated_run[a] == 0u);
        }
    }

    const uint8_t rotor_count = detector->rotor_count;
    float km_rel[PROPID_MAX_ROTORS];
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, &filter->config);
    propid_drag_per_rotor(&basis, core, km_rel, NULL);
    float kf_state[PROPID_MAX_ROTORS];
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    propid_thrust_per_rotor(&thrust, core, kf_state, NULL);
    const float adapt = detector->config.adapt_time_s;
    const float alpha = dt < adapt ? dt / adapt : 1.0f;
    detector->armed_s += dt;
    const int armed = detector->armed_s > 3.0f * adapt;
    const int derived_design = detector->config.design_loss_fraction > 0.0f;
    if (armed && derived_design && !detector->design_set) {
        derive_rotor_design(detector);
    }
    int8_t best = -1;
    float best_excess = 1.0f; /* statistic / its threshold */
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const float kf_rel = kf_state[i];
        const float weight = dt * core->rotor_speed_sq[i];
        float g[3];
        float norm_sq = 0.0f;
        float dot = 0.0f;
        for (uint8_t a = 0; a < 3u; ++a) {
            g[a] = weight * inv_sd[a] *
                   (filter->derived.thrust_torque[i][a] * kf_rel + filter->derived.drag_torque[i][a] * km_rel[i]);
            norm_sq += g[a] * g[a];
            dot += g[a] * z[a];
        }
        if (!(norm_sq > 0.0f) || !isfinite(norm_sq)) {
            detector->statistic[i] = 0.0f; /* a stopped rotor leaves no signature */
            continue;
        }
        const float norm = sqrtf(norm_sq);
        const float projection = -dot / norm;
        /* The projection of a real filter's innovations is neither centred nor
         * white: slow model error shifts it (the running mean removes that),
         * and fast correlated model error (estimates drifting under quantised
         * rotor speeds) makes successive values alike, which a CUSUM derived
         * for independent increments reads as evidence. So the deviation from
         * the running mean is also treated as an AR(1) process,
         * d_t = rho d_t-1 + e_t, whose one-step prediction error e_t is white.
         * Two standardised values: the deviation itself (right when the
         * projection is white) and e_t over its own running variance (right
         * when it is AR(1)); the CUSUM adds the smaller, so it alarms no
         * sooner than the CUSUM of either alone and the derived false-alarm
         * rate holds whenever either description does. A damage is a step and
         * passes both: its first prediction error is the whole step, and as
         * d_t-1 enters clipped at 3 running sigmas, a persisting step of s
         * sigmas keeps a prediction error of at least s - 3 rho sigmas. */
        const float sd = sqrtf(detector->var[i]);
        const float deviation = projection - detector->mean[i];
        const float rho = detector->cov1[i] > 0.0f ? detector->cov1[i] / detector->var[i] : 0.0f;
        const float correlation = rho < PROPID_DAMAGE_RHO_MAX ? rho : PROPID_DAMAGE_RHO_MAX;
        const float residual = deviation - correlation * detector->previous[i];
        const float residual_sd = sqrtf(detector->residual_var[i]);
        /* The share of the projection's variance the gyro's own white noise puts
         * in it, sum_a (g_a / |g|)^2 R / S_a: the innovation's prediction error is
         * independent of the sample's gyro noise, so no running variance can be
         * below it (docs/damage.md); both running variances are floored there. */
        float noise_share = 0.0f;
        for (uint8_t a = 0; a < 3u; ++a) {
            const float w = g[a] * inv_sd[a] / norm;
            noise_share += w * w;
        }
        const float noise_floor = filter->derived.gyro_var * noise_share;
        const float var_floor = derived_design ? noise_floor : PROPID_DAMAGE_VAR_FLOOR;
        /* The filter's own re-anchors (below) lift the projection by a known
         * amount: only a rise can look like a loss, and only a rise is taken
         * off, so every increment is at most the uncompensated one and the
         * false-alarm rate derived for those still bounds it. */
        /* An offset explains at most the rise the projection still shows: a
         * re-anchored level that grows back (the model error rebuilds the
         * rate error) takes it with it, and re-anchors in a row do not pile up. */
        const float rise_left = deviation > 0.0f ? deviation : 0.0f;
        const float offset = detector->offset[i] < rise_left ? detector->offset[i] : rise_left;
        const float offset_residual = offset - correlation * detector->offset_last[i];
        const float level = (deviation - offset) / sd;
        const float whitened = (residual - (offset_residual > 0.0f ? offset_residual : 0.0f)) / residual_sd;
        const float standard = level < whitened ? level : whitened;
        /* Update the moments with values clipped to +-3 running sigmas, so an
         * onset is not absorbed. */
        const float dev_clipped = clip_symmetric(deviation, PROPID_DAMAGE_CLIP * sd);
        const float res_clipped = clip_symmetric(residual, PROPID_DAMAGE_CLIP * residual_sd);
        detector->mean[i] += alpha * dev_clipped;
        detector->var[i] += alpha * (dev_clipped * dev_clipped - detector->var[i]);
        detector->cov1[i] += alpha * (dev_clipped * detector->previous[i] - detector->cov1[i]);
        detector->residual_var[i] += alpha * (res_clipped * res_clipped - detector->residual_var[i]);
        detector->previous[i] = dev_clipped;
        /* Floors: a near-constant projection cannot make every small wiggle a
         * many-sigma event. */
        if (!(detector->var[i] >= var_floor)) {
            detector->var[i] = var_floor;
        }
        if (!(detector->residual_var[i] >= var_floor)) {
            detector->residual_var[i] = var_floor;
        }
        /* A whole loss' shift in running sigmas, for the design: norm on the
         * first sample; the rate's gain on its axis is 1 - R / S, so the rate error
         * a persisting loss leaves grows by the share r = R / S kept after each
         * update, and over the 3 samples an alarm needs at least (the clip) the
         * shift averages first x (3 + 2 r + r^2) / 3. */
        const float kept = noise_floor < 1.0f ? noise_floor : 1.0f; /* r: S >= R */
        const float shift = norm * (3.0f + kept * (2.0f + kept)) / (3.0f * sqrtf(detector->var[i]));
        detector->loss_shift[i] = detector->loss_shift[i] > 0.0f
                                      ? detector->loss_shift[i] + alpha * (shift - detector->loss_shift[i])
                                      : shift;
        /* The offset of this sample decays as the running mean absorbs a
         * persisting step; a re-anchor on this sample adds the rise it makes in
         * the next sample's projection: the re-anchored axis' innovation loses
         * its level (the stored innovation, the rate error the re-anchor
         * removed), so that axis' share -g_a z_a / |g| leaves the projection. */
        float rise = 0.0f;
        for (uint8_t a = 0; a < 3u; ++a) {
            if (reanchored[a]) {
                rise += g[a] * z[a] / norm;
            }
        }
        detector->offset_last[i] = offset;
        detector->offset[i] = (1.0f - alpha) * offset + (rise > 0.0f ? rise : 0.0f);
        if (!armed || holding) {
            continue;
        }
        /* Clipped increment: one or two outliers (a lost or quantised telemetry
         * sample) cannot alarm alone; a damage's shift persists. */
        const float increment = standard > detector->rotor_clip[i] ? detector->rotor_clip[i] : standard;
        const float next = detector->statistic[i] + increment - detector->rotor_drift[i];
        detector->statistic[i] = next > 0.0f ? next : 0.0f;
        const float excess = detector->statistic[i] / detector->rotor_threshold[i];
        if (excess > best_excess) {
            best_excess = excess;
            best = (int8_t)i;
        }
    }
    if (best < 0) {
        return PROPID_OK;
    }
    reopen_rotor(filter, (uint8_t)best);
    detector->detections++;
    detector->damaged_mask = (uint16_t)(detector->damaged_mask | (1u << (uint8_t)best));
    detector->last_rotor = best;
    detector->last_detection_us = now;
    detector->hold_until_us = now + (uint64_t)(uint32_t)(detector->config.hold_s * 1.0e6f);
    /* Start afresh: the re-opened coefficients re-converge during the hold and
     * the running moments are re-learnt (armed again after 3 adapt times). */
    restart_bank(detector);
    *detected_rotor = best;
    return PROPID_OK;
}
