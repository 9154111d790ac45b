/* The simulator's JSON tree (sitl/io/json.h): the printer's exact layout, the
 * parser on valid and invalid texts (with where it stops), and a document
 * printed then parsed back. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"
#include "unity.h"

void setUp(void) {}
void tearDown(void) {}

static void assert_prints(const sitl_json_t *item, const char *expected)
{
    char *text = sitl_json_print(item);
    TEST_ASSERT_NOT_NULL(text);
    TEST_ASSERT_EQUAL_STRING(expected, text);
    free(text);
}

static void assert_number_prints(double x, const char *expected)
{
    sitl_json_t *n = sitl_json_number(x);
    assert_prints(n, expected);
    sitl_json_free(n);
}

static void test_numbers_print_as_integers_or_shortest_of_15_and_17_digits(void)
{
    assert_number_prints(3.0, "3");
    assert_number_prints(-7.0, "-7");
    assert_number_prints(-0.0, "0");
    assert_number_prints(0.1, "0.1");
    assert_number_prints(1.0 / 3.0, "0.33333333333333331");
    assert_number_prints(1e300, "1e+300");
    assert_number_prints(3e9, "3000000000");
    assert_number_prints(NAN, "null");
    assert_number_prints(INFINITY, "null");
}

static void test_document_layout(void)
{
    sitl_json_t *root = sitl_json_object();
    sitl_json_add(root, "name", sitl_json_string("a \"q\" \\ \n\t\x01/"));
    sitl_json_add(root, "raw", sitl_json_raw("2.50000000"));
    sitl_json_add(root, "yes", sitl_json_bool(1));
    sitl_json_add(root, "no", sitl_json_bool(0));
    sitl_json_add(root, "none", sitl_json_null());
    sitl_json_t *list = sitl_json_add(root, "list", sitl_json_array());
    sitl_json_append(list, sitl_json_number(1));
    sitl_json_t *inner = sitl_json_append(list, sitl_json_object());
    sitl_json_add(inner, "k", sitl_json_number(2));
    sitl_json_add(root, "empty_list", sitl_json_array());
    sitl_json_t *obj = sitl_json_add(root, "obj", sitl_json_object());
    sitl_json_add(obj, "empty", sitl_json_object());
    assert_prints(root, "{\n"
                        "\t\"name\":\t\"a \\\"q\\\" \\\\ \\n\\t\\u0001/\",\n"
                        "\t\"raw\":\t2.50000000,\n"
                        "\t\"yes\":\ttrue,\n"
                        "\t\"no\":\tfalse,\n"
                        "\t\"none\":\tnull,\n"
                        "\t\"list\":\t[1, {\n"
                        "\t\t\t\"k\":\t2\n"
                        "\t\t}],\n"
                        "\t\"empty_list\":\t[],\n"
                        "\t\"obj\":\t{\n"
                        "\t\t\"empty\":\t{\n"
                        "\t\t}\n"
                        "\t}\n"
                        "}");
    sitl_json_free(root);
    TEST_ASSERT_NULL(sitl_json_print(NULL));
}

static void test_add_to_null_or_wrong_container_frees_the_item(void)
{
    TEST_ASSERT_NULL(sitl_json_add(NULL, "k", sitl_json_number(1)));
    TEST_ASSERT_NULL(sitl_json_append(NULL, sitl_json_number(1)));
    sitl_json_t *array = sitl_json_array();
    TEST_ASSERT_NULL(sitl_json_add(array, "k", sitl_json_number(1)));
    TEST_ASSERT_EQUAL_INT(0, sitl_json_size(array));
    sitl_json_free(array);
}

static void test_parse_values_and_lookups(void)
{
    const char *error_at = "unset";
    sitl_json_t *root = sitl_json_parse(
        " {\"a\": [1, -2.5e-3, 0, 1E2, true, false, null],\r\n\t\"s\": \"x\\u00e9\\ud83d\\ude00\\/\\\"\","
        " \"o\": {}, \"a\": 7} \n",
        &error_at);
    TEST_ASSERT_NOT_NULL(root);
    TEST_ASSERT_NULL(error_at);
    TEST_ASSERT_TRUE(sitl_json_is(root, SITL_JSON_OBJECT));
    TEST_ASSERT_EQUAL_INT(4, sitl_json_size(root));
    const sitl_json_t *a = sitl_json_member(root, "a"); /* the first "a" */
    TEST_ASSERT_TRUE(sitl_json_is(a, SITL_JSON_ARRAY));
    TEST_ASSERT_EQUAL_INT(7, sitl_json_size(a));
    TEST_ASSERT_EQUAL_DOUBLE(1.0, sitl_json_item(a, 0)->number);
    TEST_ASSERT_EQUAL_DOUBLE(-2.5e-3, sitl_json_item(a, 1)->number);
    TEST_ASSERT_EQUAL_DOUBLE(100.0, sitl_json_item(a, 3)->number);
    TEST_ASSERT_TRUE(sitl_json_is(sitl_json_item(a, 4), SITL_JSON_TRUE));
    TEST_ASSERT_TRUE(sitl_json_is(sitl_json_item(a, 5), SITL_JSON_FALSE));
    TEST_ASSERT_TRUE(sitl_json_is(sitl_json_item(a, 6), SITL_JSON_NULL));
    TEST_ASSERT_NULL(sitl_json_item(a, 7));
    TEST_ASSERT_NULL(sitl_json_item(a, -1));
    TEST_ASSERT_NULL(sitl_json_item(root, 0));
    TEST_ASSERT_NULL(sitl_json_member(a, "a"));
    TEST_ASSERT_NULL(sitl_json_member(root, "A"));
    TEST_ASSERT_EQUAL_STRING("x\xc3\xa9\xf0\x9f\x98\x80/\"", sitl_json_member(root, "s")->text);
    TEST_ASSERT_EQUAL_INT(0, sitl_json_size(sitl_json_member(root, "o")));
    sitl_json_free(root);
}

/* Each invalid text and the offset of the first byte the parser refuses. */
static void test_invalid_texts_and_where_they_fail(void)
{
    static const struct {
        const char *text;
        int offset;
    } cases[] = {
        {"", 0},
        {"   ", 3},
        {"{", 1},
        {"{\"a\" 1}", 5},
        {"{\"a\": 1,}", 8},
        {"[1, 2,]", 6},
        {"[1 2]", 3},
        {"{a: 1}", 1},
        {"01", 1},
        {"-", 1},
        {"1.", 2},
        {"1e+", 3},
        {".5", 0},
        {"+1", 0},
        {"0x10", 1},
        {"nan", 0},
        {"tru", 0},
        {"\"abc", 4},
        {"\"a\nb\"", 2},
        {"\"\\x\"", 1},
        {"\"\\u12g4\"", 1},
        {"\"\\udc00\"", 1},
        {"\"\\ud800x\"", 1},
        {"{} x", 3},
        {"[1]]", 3},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *error_at = NULL;
        sitl_json_t *root = sitl_json_parse(cases[i].text, &error_at);
        char msg[64];
        snprintf(msg, sizeof msg, "case %d: '%s'", (int)i, cases[i].text);
        TEST_ASSERT_NULL_MESSAGE(root, msg);
        TEST_ASSERT_NOT_NULL_MESSAGE(error_at, msg);
        TEST_ASSERT_EQUAL_INT_MESSAGE(cases[i].offset, (int)(error_at - cases[i].text), msg);
    }
}

static void test_nesting_limit(void)
{
    char text[2 * 66 + 1];
    for (int depth = 64; depth <= 65; depth++) {
        memset(text, '[', (size_t)depth);
        memset(text + depth, ']', (size_t)depth);
        text[2 * depth] = '\0';
        sitl_json_t *root = sitl_json_parse(text, NULL);
        if (depth == 64) {
            TEST_ASSERT_NOT_NULL(root);
        } else {
            TEST_ASSERT_NULL(root);
        }
        sitl_json_free(root);
    }
}

static void test_printed_document_parses_back(void)
{
    sitl_json_t *root = sitl_json_object();
    sitl_json_add(root, "s", sitl_json_string("tab\there \"quoted\" \x1f end"));
    sitl_json_t *list = sitl_json_add(root, "v", sitl_json_array());
    const double values[] = {0.1, -1.0 / 3.0, 6.02214076e23, 5e-324, 1.7976931348623157e308};
    for (int i = 0; i < 5; i++) {
        sitl_json_append(list, sitl_json_number(values[i]));
    }
    char *text = sitl_json_print(root);
    TEST_ASSERT_NOT_NULL(text);
    sitl_json_t *back = sitl_json_parse(text, NULL);
    TEST_ASSERT_NOT_NULL(back);
    TEST_ASSERT_EQUAL_STRING("tab\there \"quoted\" \x1f end", sitl_json_member(back, "s")->text);
    const sitl_json_t *v = sitl_json_member(back, "v");
    for (int i = 0; i < 5; i++) {
        TEST_ASSERT_TRUE(sitl_json_item(v, i)->number == values[i]);
    }
    char *again = sitl_json_print(back);
    TEST_ASSERT_EQUAL_STRING(text, again);
    free(again);
    free(text);
    sitl_json_free(back);
    sitl_json_free(root);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_numbers_print_as_integers_or_shortest_of_15_and_17_digits);
    RUN_TEST(test_document_layout);
    RUN_TEST(test_add_to_null_or_wrong_container_frees_the_item);
    RUN_TEST(test_parse_values_and_lookups);
    RUN_TEST(test_invalid_texts_and_where_they_fail);
    RUN_TEST(test_nesting_limit);
    RUN_TEST(test_printed_document_parses_back);
    return UNITY_END();
}
