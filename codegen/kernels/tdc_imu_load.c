/*
 * tdc_imu_load.c -- codegen kernel library: the IMU module's calibration loader (blob decoding,
 * CRC-32, the bounds checks of cubic and piecewise-linear tables, NAME_load). Static C:
 * codegen/imu.py copies it, from its first section line (blob decoding) on, into each generated
 * IMU module, with the module's prefix in place of tdcimu_ and TDCIMU_. Not compiled on its own:
 * it uses the module's NAME_calibration_t, NAME_channel_t and NAME_ macros.
 */

/* ---- blob decoding: little-endian, byte by byte (any alignment, any host byte order) -------- */

static uint32_t tdcimu_u16(const uint8_t *b)
{
    return (uint32_t)b[0] | ((uint32_t)b[1] << 8);
}

static uint32_t tdcimu_u32(const uint8_t *b)
{
    return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
}

static int32_t tdcimu_i32(const uint8_t *b)
{
    uint32_t u = tdcimu_u32(b);
    /* two's complement without an implementation-defined conversion */
    return (u & UINT32_C(0x80000000)) != 0u ? -(int32_t)(UINT32_C(0xFFFFFFFF) - u) - 1 : (int32_t)u;
}

static int64_t tdcimu_i64(const uint8_t *b)
{
    uint64_t u = (uint64_t)tdcimu_u32(b) | ((uint64_t)tdcimu_u32(b + 4) << 32);
    return (u & (UINT64_C(1) << 63)) != 0u ? -(int64_t)(UINT64_MAX - u) - 1 : (int64_t)u;
}

/* CRC-32 (IEEE 802.3, reflected, as zlib.crc32), bitwise: small code, init-time only. */
static uint32_t tdcimu_crc32(const uint8_t *data, size_t n)
{
    uint32_t crc = UINT32_C(0xFFFFFFFF);
    size_t i;
    unsigned bit;
    for (i = 0u; i < n; ++i) {
        crc ^= (uint32_t)data[i];
        for (bit = 0u; bit < 8u; ++bit) {
            crc = (crc >> 1) ^ (UINT32_C(0xEDB88320) & (0u - (crc & 1u)));
        }
    }
    return ~crc;
}

static uint64_t tdcimu_magnitude(int64_t v)
{
    return v < 0 ? 0u - (uint64_t)v : (uint64_t)v;
}

/* A cubic channel's tables keep |Horner accumulator * u| below 2^62 (the quantiser's proof). */
static int tdcimu_cubic_ok(const tdcimu_channel_t *ch)
{
    uint64_t sum = 3u;
    unsigned j;
    if (ch->u_shift < 1u || ch->u_shift > 31u || ch->frac > 62u || ch->clip_lo >= ch->clip_hi ||
        ch->t_ref < ch->clip_lo || ch->t_ref > ch->clip_hi) {
        return 0;
    }
    if ((uint64_t)((int64_t)ch->t_ref - ch->clip_lo) > (UINT64_C(1) << ch->u_shift) ||
        (uint64_t)((int64_t)ch->clip_hi - ch->t_ref) > (UINT64_C(1) << ch->u_shift)) {
        return 0;
    }
    for (j = 0u; j < 4u; ++j) {
        sum += tdcimu_magnitude(ch->coefficient[j]);
    }
    return sum < (TDCIMU_SAFE >> ch->u_shift);
}

/* A piecewise-linear channel's |slope T + intercept| stays below 2^62 for every clamped T. */
static int tdcimu_pla_ok(const tdcimu_channel_t *ch)
{
    uint64_t t_max;
    uint32_t k;
    if (ch->frac > 62u || ch->clip_lo >= ch->clip_hi || ch->n_splits >= TDCIMU_MAX_INTERVALS) {
        return 0;
    }
    t_max = tdcimu_magnitude(ch->clip_lo) > tdcimu_magnitude(ch->clip_hi) ? tdcimu_magnitude(ch->clip_lo)
                                                                          : tdcimu_magnitude(ch->clip_hi);
    for (k = 0u; k + 1u < ch->n_splits; ++k) {
        if (ch->split[k] > ch->split[k + 1u]) {
            return 0;
        }
    }
    for (k = 0u; k <= ch->n_splits; ++k) {
        uint64_t product = tdcimu_magnitude(ch->slope[k]) * t_max; /* < 2^31 * 2^31 */
        uint64_t intercept = tdcimu_magnitude(ch->intercept[k]);
        if (product >= TDCIMU_SAFE || intercept >= TDCIMU_SAFE - product) {
            return 0;
        }
    }
    return 1;
}

static int tdcimu_decode(tdcimu_calibration_t *cal, const uint8_t *blob, size_t size)
{
    size_t pos, end;
    uint32_t k, j;
    if (blob == NULL || size < TDCIMU_BLOB_HEADER + 4u) {
        return TDCIMU_ERR_SIZE;
    }
    if (blob[0] != 0x54u || blob[1] != 0x44u || blob[2] != 0x43u || blob[3] != 0x43u) { /* "TDCC" */
        return TDCIMU_ERR_MAGIC;
    }
    if (tdcimu_u16(blob + 4) != TDCIMU_BLOB_VERSION) {
        return TDCIMU_ERR_VERSION;
    }
    end = size - 4u;
    if (tdcimu_crc32(blob, end) != tdcimu_u32(blob + end)) {
        return TDCIMU_ERR_CRC;
    }
    if (tdcimu_u16(blob + 6) != TDCIMU_CHANNELS || tdcimu_u16(blob + 8) != TDCIMU_SENSORS ||
        tdcimu_u16(blob + 10) != TDCIMU_MAX_INTERVALS || tdcimu_u32(blob + 12) != TDCIMU_MODULE_ID) {
        return TDCIMU_ERR_MODULE_ID;
    }
    cal->module_id = TDCIMU_MODULE_ID;
    for (j = 0u; j < 32u; ++j) {
        cal->sha256[j] = blob[16u + j];
    }
    pos = TDCIMU_BLOB_HEADER;
    if (end - pos < 8u * TDCIMU_SENSORS) {
        return TDCIMU_ERR_SIZE;
    }
    for (k = 0u; k < TDCIMU_SENSORS; ++k, pos += 8u) {
        cal->valid_lo[k] = tdcimu_i32(blob + pos);
        cal->valid_hi[k] = tdcimu_i32(blob + pos + 4u);
        if (cal->valid_lo[k] > cal->valid_hi[k]) {
            return TDCIMU_ERR_TABLE;
        }
    }
    for (k = 0u; k < TDCIMU_CHANNELS; ++k) {
        tdcimu_channel_t *ch = &cal->channel[k];
        uint32_t intervals;
        if (end - pos < TDCIMU_CHANNEL_HEADER) {
            return TDCIMU_ERR_SIZE;
        }
        ch->kind = blob[pos];
        ch->sensor = blob[pos + 1u];
        ch->frac = blob[pos + 2u];
        ch->u_shift = blob[pos + 3u];
        intervals = tdcimu_u16(blob + pos + 4u);
        ch->clip_lo = tdcimu_i32(blob + pos + 8u);
        ch->clip_hi = tdcimu_i32(blob + pos + 12u);
        ch->t_ref = tdcimu_i32(blob + pos + 16u);
        pos += TDCIMU_CHANNEL_HEADER;
        if (ch->sensor >= TDCIMU_SENSORS) {
            return TDCIMU_ERR_TABLE;
        }
        if (ch->kind == TDCIMU_KIND_CUBIC) {
            if (intervals != 0u) {
                return TDCIMU_ERR_TABLE;
            }
            if (end - pos < 16u) {
                return TDCIMU_ERR_SIZE;
            }
            for (j = 0u; j < 4u; ++j, pos += 4u) {
                ch->coefficient[j] = tdcimu_i32(blob + pos);
            }
            if (!tdcimu_cubic_ok(ch)) {
                return TDCIMU_ERR_TABLE;
            }
        } else if (ch->kind == TDCIMU_KIND_PLA) {
            if (intervals < 1u || intervals > TDCIMU_MAX_INTERVALS) {
                return TDCIMU_ERR_TABLE;
            }
            if (end - pos < 16u * (size_t)intervals - 4u) { /* 4 (split) + 4 (slope) + 8 (intercept) per interval, less one split */
                return TDCIMU_ERR_SIZE;
            }
            ch->n_splits = intervals - 1u;
            for (j = 0u; j < ch->n_splits; ++j, pos += 4u) {
                ch->split[j] = tdcimu_i32(blob + pos);
            }
            for (j = 0u; j < intervals; ++j, pos += 4u) {
                ch->slope[j] = tdcimu_i32(blob + pos);
            }
            for (j = 0u; j < intervals; ++j, pos += 8u) {
                ch->intercept[j] = tdcimu_i64(blob + pos);
            }
            if (!tdcimu_pla_ok(ch)) {
                return TDCIMU_ERR_TABLE;
            }
        } else {
            return TDCIMU_ERR_TABLE;
        }
    }
    return pos == end ? TDCIMU_OK : TDCIMU_ERR_SIZE;
}

static void tdcimu_clear(tdcimu_calibration_t *cal)
{
    unsigned char *bytes = (unsigned char *)cal; /* the object representation: defined for any type */
    size_t i;
    for (i = 0u; i < sizeof *cal; ++i) {
        bytes[i] = 0u;
    }
}

int tdcimu_load(tdcimu_calibration_t *cal, const uint8_t *blob, size_t size)
{
    int status;
    tdcimu_clear(cal);
    status = tdcimu_decode(cal, blob, size);
    if (status != TDCIMU_OK) {
        tdcimu_clear(cal);
    }
    return status;
}
