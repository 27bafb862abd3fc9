/**
 * @file gl_mav_fxparams.c
 * @brief The parameter table of a fixed-point law (gl_mav_fxset.h): the integer gains, staged, checked and committed
 *        through GL_HASH. The same API as gl_mav_params.c, which a float32 build compiles instead.
 */
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "gainlink/gl_hex.h"
#include "gl_mav_params.h"

/* Where each group of values starts in gl_mav_fx_set_t::v (the index order of gl_mav_fxset.h). */
#define OFF_UOPV (2 * GL_FX_TERMS)
#define OFF_LOV (OFF_UOPV + GL_FX_M)
#define OFF_HIV (OFF_LOV + GL_FX_M)
#define OFF_UOPU (OFF_HIV + GL_FX_M)
#define OFF_USAFE (OFF_UOPU + GL_FX_M)
#define OFF_YOP (OFF_USAFE + GL_FX_M)
#define OFF_XH0 (OFF_YOP + GL_FX_P)
#define OFF_Z0 (OFF_XH0 + GL_FX_N)
_Static_assert(OFF_Z0 + GL_FX_Q == GL_MAV_FX_VALUES, "value layout");

#define WORD_MAX ((int32_t)((1ul << (GL_FX_WORD_BITS - 1)) - 1ul))
#define HEADER_SIG GL_GAINS_STRUCTURE_FIELDS
#define HEADER_STRUCT (GL_GAINS_STRUCTURE_FIELDS + 1)

#define GL_HEADER_ID(field, compiled, param) param,
static const char *const header_ids[GL_MAV_HEADER_PARAMS] = {
    GL_GAINS_STRUCTURE(GL_HEADER_ID) "GL_FX_SIG", "GL_FX_STRUCT", "GL_HASH"};

/** CRC-32 (zlib's) of `n` int32 words taken as little-endian bytes, continuing `crc` (0 to start). */
static uint32_t crc_words(uint32_t crc, const int32_t *w, size_t n)
{
    uint32_t c = ~crc;
    for (size_t k = 0; k < n; ++k) {
        for (unsigned b = 0; b < 4u; ++b) {
            c ^= ((uint32_t)w[k] >> (8u * b)) & 0xFFu;
            for (unsigned i = 0; i < 8u; ++i) {
                c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
            }
        }
    }
    return ~c;
}

/** A table's int16/int8/uint8/uint16 entries as int32 words, into the CRC. */
#define CRC_ARRAY(crc, array, count)                                                                                 \
    do {                                                                                                             \
        for (size_t k_ = 0; k_ < (size_t)(count); ++k_) {                                                            \
            const int32_t w_ = (int32_t)(array)[k_];                                                                 \
            (crc) = crc_words((crc), &w_, 1u);                                                                       \
        }                                                                                                            \
    } while (0)

/** GL_FX_STRUCT: what is compiled in besides the formats (gl_mav_fxset.h). */
static uint32_t structure_crc(const gl_fixed_gains_t *g)
{
    uint32_t c = 0u;
    CRC_ARRAY(c, g->signal, GL_FX_TERMS);
    CRC_ARRAY(c, g->row_end, GL_FX_ROWS);
    c = crc_words(c, g->key_y_lo, GL_FX_P);
    c = crc_words(c, g->key_y_hi, GL_FX_P);
    c = crc_words(c, g->key_r_lo, GL_FX_Q);
    c = crc_words(c, g->key_r_hi, GL_FX_Q);
    CRC_ARRAY(c, g->y_lo, GL_FX_P);
    CRC_ARRAY(c, g->y_hi, GL_FX_P);
    CRC_ARRAY(c, g->r_lo, GL_FX_Q);
    CRC_ARRAY(c, g->r_hi, GL_FX_Q);
    return c;
}

static uint32_t signature_word(void)
{
    uint64_t v = 0u;
    (void)gl_hex_parse(GL_FX_SIGNATURE, sizeof GL_FX_SIGNATURE - 1u, &v);
    return (uint32_t)v;
}

/** The gain parameters' values of `g`. */
static void values_of(const gl_fixed_gains_t *g, int32_t *v)
{
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        v[2u * k] = g->coef[k];
        v[2u * k + 1u] = g->shift[k];
    }
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        v[OFF_UOPV + i] = g->uop_v[i];
        v[OFF_LOV + i] = g->lo_v[i];
        v[OFF_HIV + i] = g->hi_v[i];
        v[OFF_UOPU + i] = g->uop_u[i];
        v[OFF_USAFE + i] = g->u_safe[i];
    }
    for (unsigned k = 0; k < GL_FX_P; ++k) {
        v[OFF_YOP + k] = g->yop[k];
    }
    memcpy(&v[OFF_XH0], g->xh0, sizeof(int32_t) * GL_FX_N);
    for (int j = 0; j < GL_FX_Q; ++j) {
        v[OFF_Z0 + j] = g->z0[j];
    }
}

static int fits_word(int32_t x)
{
    return x >= -WORD_MAX - 1 && x <= WORD_MAX;
}

/** The checks of a candidate's values (gl_mav_fxset.h, GL_HASH): 1 when they hold. */
static int values_ok(const int32_t *v)
{
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        if (!fits_word(v[2u * k]) || v[2u * k + 1u] < 0 || v[2u * k + 1u] > 62) {
            return 0;
        }
    }
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        if (v[OFF_LOV + i] > v[OFF_HIV + i] || !fits_word(v[OFF_UOPU + i]) || !fits_word(v[OFF_USAFE + i])) {
            return 0;
        }
    }
    for (unsigned k = 0; k < GL_FX_P; ++k) {
        if (!fits_word(v[OFF_YOP + k])) {
            return 0;
        }
    }
    return 1;
}

/** Put checked values into `g` (its structure and formats stay the compiled ones). */
static void apply_values(const int32_t *v, gl_fixed_gains_t *g)
{
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        g->coef[k] = (gl_fx_coef_t)v[2u * k];
        g->shift[k] = (uint8_t)v[2u * k + 1u];
    }
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        g->uop_v[i] = v[OFF_UOPV + i];
        g->lo_v[i] = v[OFF_LOV + i];
        g->hi_v[i] = v[OFF_HIV + i];
        g->uop_u[i] = (gl_fx_word_t)v[OFF_UOPU + i];
        g->u_safe[i] = (gl_fx_word_t)v[OFF_USAFE + i];
    }
    for (unsigned k = 0; k < GL_FX_P; ++k) {
        g->yop[k] = (gl_fx_word_t)v[OFF_YOP + k];
    }
    memcpy(g->xh0, &v[OFF_XH0], sizeof(int32_t) * GL_FX_N);
    for (int j = 0; j < GL_FX_Q; ++j) {
        g->z0[j] = v[OFF_Z0 + j];
    }
}

const gl_mav_fx_set_t *gl_mav_fx_default(void)
{
    static gl_mav_fx_set_t set;
    static int made;
    if (!made) {
        set.g = gl_fixed_gains_default;
        values_of(&set.g, set.v);
        set.crc32 = crc_words(0u, set.v, GL_MAV_FX_VALUES);
        made = 1;
    }
    return &set;
}

/** Block name, row i and column j of term k in row `row` (the artifact's names: gl_mav_fxset.h). */
static const char *term_block(unsigned row, unsigned signal, unsigned *i, unsigned *j)
{
    static const struct { unsigned start, end; const char *v, *z, *x; } groups[] = {
        {GL_FX_SIG_XH, GL_FX_SIG_DY, "KX", "?", "F"}, {GL_FX_SIG_DY, GL_FX_SIG_Z, "KY", "?", "LY"},
        {GL_FX_SIG_Z, GL_FX_SIG_DU, "KZ", "?", "?"},  {GL_FX_SIG_DU, GL_FX_SIG_R, "?", "?", "G"},
        {GL_FX_SIG_R, GL_FX_SIG_Y, "?", "TR", "?"},   {GL_FX_SIG_Y, GL_FX_SIG_W, "?", "TY", "?"},
        {GL_FX_SIG_W, GL_FX_SIGNALS, "?", "KAW", "?"},
    };
    const int kind = row < GL_FX_M ? 0 : (row < GL_FX_M + GL_FX_Q ? 1 : 2);
    *i = kind == 0 ? row : (kind == 1 ? row - GL_FX_M : row - GL_FX_M - GL_FX_Q);
    for (size_t k = 0; k < sizeof groups / sizeof groups[0]; ++k) {
        if (signal >= groups[k].start && signal < groups[k].end) {
            *j = signal - groups[k].start;
            return kind == 0 ? groups[k].v : (kind == 1 ? groups[k].z : groups[k].x);
        }
    }
    *j = 0u;
    return "?";
}

static void add_param(gl_mav_params_t *table, const char *name, int32_t header, uint32_t offset)
{
    gl_mav_param_t *p = &table->param[table->count++];
    size_t len = 0u; /* at most the 16 characters of an id, and no further than the name's NUL */
    while (len < GL_MAV_ID_LEN && name[len] != '\0') {
        ++len;
    }
    memcpy(p->id, name, len);
    p->id[len] = '\0';
    p->type = GL_MAV_TYPE_INT32;
    p->header = header;
    p->offset = offset;
}

static void add_terms(gl_mav_params_t *table, const gl_fixed_gains_t *g)
{
    unsigned row = 0u;
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        while (row < GL_FX_ROWS && k >= g->row_end[row]) {
            ++row;
        }
        unsigned i = 0u, j = 0u;
        const char *block = term_block(row, g->signal[k], &i, &j);
        char name[48]; /* i, j < 64: every id fits the 16 characters */
        snprintf(name, sizeof name, "GL_%s_%u_%u", block, i, j);
        add_param(table, name, -1, 2u * k);
        snprintf(name, sizeof name, "GL_%sE_%u_%u", block, i, j);
        add_param(table, name, -1, 2u * k + 1u);
    }
}

static void add_vector(gl_mav_params_t *table, const char *stem, uint32_t offset, unsigned count)
{
    for (unsigned i = 0; i < count; ++i) {
        char name[48];
        snprintf(name, sizeof name, "GL_%s_%u", stem, i);
        add_param(table, name, -1, offset + i);
    }
}

void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    memset(table, 0, sizeof *table);
    for (int32_t h = 0; h < GL_MAV_HEADER_PARAMS; ++h) {
        add_param(table, header_ids[h], h, 0u);
    }
    add_terms(table, &gains->g);
    add_vector(table, "UOPV", OFF_UOPV, GL_FX_M);
    add_vector(table, "LOV", OFF_LOV, GL_FX_M);
    add_vector(table, "HIV", OFF_HIV, GL_FX_M);
    add_vector(table, "UOPU", OFF_UOPU, GL_FX_M);
    add_vector(table, "USAFE", OFF_USAFE, GL_FX_M);
    add_vector(table, "YOP", OFF_YOP, GL_FX_P);
    add_vector(table, "XH0", OFF_XH0, GL_FX_N);
    add_vector(table, "Z0", OFF_Z0, GL_FX_Q);
    table->staged = *gains;
    table->committed = *gains;
}

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const gl_mav_param_t *p = &table->param[index];
    if (p->header >= 0 && p->header < GL_GAINS_STRUCTURE_FIELDS) {
#define GL_STRUCTURE_WORD(field, compiled, param) (uint32_t)(compiled),
        const uint32_t words[GL_GAINS_STRUCTURE_FIELDS] = {GL_GAINS_STRUCTURE(GL_STRUCTURE_WORD)};
        return gl_mav_float_of_bits(words[p->header]);
    }
    if (p->header == HEADER_SIG) {
        return gl_mav_float_of_bits(signature_word());
    }
    if (p->header == HEADER_STRUCT) {
        return gl_mav_float_of_bits(structure_crc(&table->committed.g));
    }
    if (p->header == GL_MAV_HASH_HEADER) {
        return gl_mav_float_of_bits(table->committed.crc32);
    }
    return gl_mav_float_of_bits((uint32_t)table->staged.v[p->offset]);
}

/** Check a candidate set and build its integers: GL_OK, GL_ERR_CRC or GL_ERR_RANGE (then `set` is unusable). */
static gl_status_t check_set(gl_mav_set_t *set)
{
    if (crc_words(0u, set->v, GL_MAV_FX_VALUES) != set->crc32) {
        return GL_ERR_CRC;
    }
    if (!values_ok(set->v)) {
        return GL_ERR_RANGE;
    }
    apply_values(set->v, &set->g);
    return GL_OK;
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    static gl_mav_set_t candidate; /* large: not on the stack */
    candidate = *gains;
    gl_status_t st = check_set(&candidate);
    if (st != GL_OK) {
        return st;
    }
    table->staged = candidate;
    table->committed = candidate;
    table->commits++;
    return GL_OK;
}

uint32_t gl_mav_params_bits(const gl_mav_set_t *set, uint32_t offset)
{
    return (uint32_t)set->v[offset];
}

void gl_mav_params_put_bits(gl_mav_set_t *set, uint32_t offset, uint32_t bits)
{
    set->v[offset] = (int32_t)bits;
}
