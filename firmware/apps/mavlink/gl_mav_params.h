/**
 * @file gl_mav_params.h
 * @brief MAVLink parameter table over a staged ::gl_gains_t, with an atomic commit through GL_HASH.
 *
 * Naming scheme (index order; the ids come from the field table gainlink.shipping.gains_layout, which
 * runtime/mavlink/params.py reads too):
 * - `GL_DIM_N GL_DIM_M GL_DIM_P GL_DIM_Q GL_FORM GL_AW` (INT32, read-only): compiled structure.
 * - `GL_HASH` (INT32): CRC-32 of the committed gain set (gl_gains_crc32()). Setting it to the CRC of the
 *   staged set commits that set; any other value, or a staged set that fails gl_gains_check() /
 *   derivation, is refused and the committed set stays.
 * - REAL32, one per number of ::gl_gains_t in declaration order: `GL_TS`, `GL_AD_i_j`, `GL_BD_i_j`,
 *   `GL_CD_i_j`, `GL_DD_i_j`, `GL_K_i_j`, `GL_L_i_j`, `GL_M_i_j` (current-estimator form only),
 *   `GL_CI_i_j`, `GL_KI_i_j`, `GL_KAW_i_j` (q > 0 only), `GL_UMIN_i`, `GL_UMAX_i`, `GL_XH0_i`,
 *   `GL_Z0_i` (q > 0 only), `GL_UOP_i`, `GL_YOP_i` (the operating point). Setting one stages it (non-finite
 *   values are refused); it reads back staged.
 * A fixed-point law's build (GL_MAV_LAW_FIXED) has the table of gl_mav_fxset.h instead (gl_mav_fxparams.c, the same
 * functions over ::gl_mav_set_t, its integers). A scheduled law's build (GL_MAV_LAW_SCHED) has the table of
 * gl_mav_schedparams.c: `GL_DIM_N GL_DIM_M GL_DIM_P GL_DIM_Q GL_NPTS GL_DIM_E` (INT32, read-only), `GL_HASH` (the
 * CRC-32 of the bytes of its tables, gl_sched_tables_t), then REAL32 every float of the tables in declaration order:
 * `GL_S_k`, per point k `GL_KX_k_i_j GL_KY_k_i_j GL_KZ_k_i_j GL_F_k_i_j GL_G_k_i_j GL_LY_k_i_j` (each block for every
 * point before the next block), `GL_UOP_k_i`, then `GL_UMIN_i GL_UMAX_i GL_CI_i_j GL_ALPHA GL_RATE`. Committing
 * through GL_HASH checks the CRC and gl_sched_init() on the staged tables: all points change together, or none.
 */
#ifndef GL_MAV_PARAMS_H
#define GL_MAV_PARAMS_H

#include <stdint.h>

#include "gl_mav_law.h"
#if !(defined(GL_MAV_LAW_SCHED) && GL_MAV_LAW_SCHED)
#include "gainlink/gl_loop.h"
#endif

/** Length of a MAVLink parameter id (not NUL-terminated when full). */
#define GL_MAV_ID_LEN 16

#if defined(GL_MAV_LAW_FIXED) && GL_MAV_LAW_FIXED
/* A fixed-point law: the table holds its integers (gl_mav_fxparams.c; naming in gl_mav_fxset.h). */
#include "gl_mav_fxset.h"
/** Read-only structure parameters, GL_FX_SIG, GL_FX_STRUCT, plus GL_HASH. */
#define GL_MAV_HEADER_PARAMS (GL_GAINS_STRUCTURE_FIELDS + 3)
/** Number of parameters (every integer gain plus the header ones). */
#define GL_MAV_MAX_PARAMS (GL_MAV_HEADER_PARAMS + GL_MAV_FX_VALUES)
/** A gain set of the table: the integers, their parameter values and their CRC-32. */
typedef gl_mav_fx_set_t gl_mav_set_t;
/** The compiled set. */
#define GL_MAV_DEFAULT_SET gl_mav_fx_default()
#elif defined(GL_MAV_LAW_SCHED) && GL_MAV_LAW_SCHED
/** Structure (n, m, p, q, points, external signals; read-only) plus GL_HASH. */
#define GL_MAV_HEADER_PARAMS 7
/** Number of parameters: every float of the tables plus the header ones. */
#define GL_MAV_MAX_PARAMS (GL_MAV_HEADER_PARAMS + (int)(sizeof(gl_sched_tables_t) / sizeof(float)))
/** A gain set of the table: the tables (by value: the loop runs on the committed ones) and their CRC-32. */
typedef struct gl_mav_sched_set {
    gl_sched_tables_t t; /**< The tables. */
    uint32_t crc32;      /**< CRC-32 of their bytes (GL_HASH). */
} gl_mav_set_t;
/** @brief The compiled set (gl_sched_default). @return It. */
const gl_mav_set_t *gl_mav_sched_default_set(void);
#define GL_MAV_DEFAULT_SET gl_mav_sched_default_set()
#else
/** Read-only structure parameters plus GL_HASH. */
#define GL_MAV_HEADER_PARAMS (GL_GAINS_STRUCTURE_FIELDS + 1)

/** Upper bound of the number of parameters (every float of gl_gains_t plus the header ones). */
#define GL_MAV_MAX_PARAMS (GL_MAV_HEADER_PARAMS + GL_GAINS_FLOATS)
/** A gain set of the table: the float32 loop's. */
typedef gl_gains_t gl_mav_set_t;
/** The compiled set. */
#define GL_MAV_DEFAULT_SET (&gl_gains_default)
#endif

/** Index of GL_HASH among the header parameters: the last of them, in every law's table. */
#define GL_MAV_HASH_HEADER (GL_MAV_HEADER_PARAMS - 1)

_Static_assert(GL_MAV_MAX_PARAMS < 65535, "too many parameters for MAVLink's uint16 param_index");

/** MAV_PARAM_TYPE values used here. */
#define GL_MAV_TYPE_INT32 6
#define GL_MAV_TYPE_REAL32 9

/** Outcome of a parameter set. */
typedef enum gl_mav_set_result {
    GL_MAV_SET_OK = 0,        /**< Accepted (staged, or committed for GL_HASH). */
    GL_MAV_SET_UNKNOWN = 1,   /**< No such parameter. */
    GL_MAV_SET_READ_ONLY = 2, /**< Structure parameter. */
    GL_MAV_SET_BAD_TYPE = 3,  /**< param_type differs from the parameter's. */
    GL_MAV_SET_BAD_VALUE = 4, /**< Non-finite value, or a commit the library refused. */
} gl_mav_set_result_t;

/** One parameter: id, type and where its value lives. */
typedef struct gl_mav_param {
    char id[GL_MAV_ID_LEN + 1]; /**< NUL-terminated id. */
    uint8_t type;               /**< GL_MAV_TYPE_*. */
    int32_t header;             /**< Structure field index, GL_GAINS_STRUCTURE_FIELDS for GL_HASH, -1 a float. */
    uint32_t offset;            /**< Float index from gl_gains_t::Ts (floats only; fixed point: index into v). */
} gl_mav_param_t;

/** The table and the two gain sets it works on. Caller-owned (static storage). */
typedef struct gl_mav_params {
    gl_mav_param_t param[GL_MAV_MAX_PARAMS]; /**< Parameters in index order. */
    uint16_t count;                          /**< Number of parameters. */
    gl_mav_set_t staged;                     /**< Values as set, not yet committed. */
    gl_mav_set_t committed;                  /**< The set the loop runs on (from its next step). */
    uint32_t commits;                        /**< Number of accepted commits. */
    int32_t last_refusal;                    /**< gl_status_t of the last refused commit (0 if none). */
} gl_mav_params_t;

/**
 * @brief Build the table and set both sets to `gains`.
 * @param[out] table  Table.
 * @param[in]  gains  Initial (committed) set; its crc32 must be valid.
 */
void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains);

/**
 * @brief Index of a parameter by id.
 * @param[in] table  Table.
 * @param[in] id     Id, at most 16 characters, need not be NUL-terminated when 16 long.
 * @return Its index, or -1.
 */
int32_t gl_mav_params_find(const gl_mav_params_t *table, const char *id);

/**
 * @brief A word's 32 bits as a float (a param_value carrying an integer bytewise).
 * @param[in] bits The bits. @return The float with those bits.
 */
float gl_mav_float_of_bits(uint32_t bits);

/**
 * @brief The four param_value bytes of a parameter (bytewise encoding for integers).
 * @param[in] table  Table.
 * @param[in] index  Parameter index (< count).
 * @return The value's bits as a float (integers: their bytes).
 */
float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index);

/**
 * @brief Set a parameter from a PARAM_SET.
 * @param[in,out] table  Table.
 * @param[in]     index  Parameter index (< count).
 * @param[in]     value  param_value as received (integers bytewise).
 * @param[in]     type   param_type as received.
 * @return GL_MAV_SET_OK or why it was refused (nothing changed then).
 */
gl_mav_set_result_t gl_mav_params_set(gl_mav_params_t *table, uint16_t index, float value, uint8_t type);

/**
 * @brief Replace both sets (a reload or a reset); `gains` must pass gl_gains_check().
 * @param[in,out] table  Table.
 * @param[in]     gains  New committed set.
 * @return GL_OK, or the check's error and nothing changed.
 */
gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains);

/**
 * @brief The stored bits of a gain parameter (gl_mav_store.c): a float's or an integer's 32 bits.
 * @param[in] set A gain set. @param[in] offset The parameter's ::gl_mav_param_t::offset. @return The bits.
 */
uint32_t gl_mav_params_bits(const gl_mav_set_t *set, uint32_t offset);

/**
 * @brief Put a gain parameter's stored bits into a set (gl_mav_store.c; checked when the set is committed).
 * @param[in,out] set A gain set. @param[in] offset The parameter's offset. @param[in] bits The bits.
 */
void gl_mav_params_put_bits(gl_mav_set_t *set, uint32_t offset, uint32_t bits);

#endif /* GL_MAV_PARAMS_H */
