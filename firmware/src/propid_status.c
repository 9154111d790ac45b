/* Names of the status codes, for logs and host tools. */
#include "propid/propid.h"

const char *propid_status_name(propid_status_t status)
{
    switch (status) {
    case PROPID_OK: return "PROPID_OK";
    case PROPID_OK_GATED: return "PROPID_OK_GATED";
    case PROPID_OK_QUEUED: return "PROPID_OK_QUEUED";
    case PROPID_ERR_NULL: return "PROPID_ERR_NULL";
    case PROPID_ERR_NOT_INITIALISED: return "PROPID_ERR_NOT_INITIALISED";
    case PROPID_ERR_CONFIG: return "PROPID_ERR_CONFIG";
    case PROPID_ERR_NOT_FINITE: return "PROPID_ERR_NOT_FINITE";
    case PROPID_ERR_ROTOR_SPEED_NEGATIVE: return "PROPID_ERR_ROTOR_SPEED_NEGATIVE";
    case PROPID_ERR_ROTOR_SPEED_RANGE: return "PROPID_ERR_ROTOR_SPEED_RANGE";
    case PROPID_ERR_ROTOR_COUNT: return "PROPID_ERR_ROTOR_COUNT";
    case PROPID_ERR_ROTOR_INDEX: return "PROPID_ERR_ROTOR_INDEX";
    case PROPID_ERR_GYRO_RANGE: return "PROPID_ERR_GYRO_RANGE";
    case PROPID_ERR_TIME_BACKWARDS: return "PROPID_ERR_TIME_BACKWARDS";
    case PROPID_ERR_TIME_JUMP: return "PROPID_ERR_TIME_JUMP";
    case PROPID_ERR_NO_ROTOR_DATA: return "PROPID_ERR_NO_ROTOR_DATA";
    case PROPID_ERR_ROTOR_STALE: return "PROPID_ERR_ROTOR_STALE";
    case PROPID_ERR_NUMERIC: return "PROPID_ERR_NUMERIC";
    case PROPID_ERR_ACCEL_RANGE: return "PROPID_ERR_ACCEL_RANGE";
    default: return "PROPID_UNKNOWN_STATUS";
    }
}
