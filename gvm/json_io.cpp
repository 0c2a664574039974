#include "gvm/json_io.h"

#include <string>

namespace collido::gvm {

nlohmann::json machine_to_json(const MachineParams& p) {
  nlohmann::json j;
  j["kind"] = "general-vector-machine";
  j["version"] = 1;
  j["activation"] = activation_name(p.activation);
  j["inputs"] = p.inputs;
  j["outputs"] = p.outputs;
  j["hidden"] = p.hidden;
  j["input_names"] = p.input_names;
  j["output_names"] = p.output_names;
  j["in_min"] = p.in_min;
  j["in_max"] = p.in_max;
  j["out_min"] = p.out_min;
  j["out_max"] = p.out_max;
  j["out_a"] = p.out_a;
  j["out_c"] = p.out_c;
  j["w_max"] = p.w_max;
  j["b_max"] = p.b_max;
  j["beta_max"] = p.beta_max;
  j["w"] = p.w;
  j["b"] = p.b;
  j["beta"] = p.beta;
  j["v"] = p.v;
  return j;
}

Expected<MachineParams> machine_from_json(const nlohmann::json& j) {
  // nlohmann reports wrong types by throwing; keep that inside the module.
  try {
    if (!j.is_object() || j.value("kind", "") != "general-vector-machine")
      return parse_error("not a general-vector-machine JSON object");
    if (integer_at<int>(j, "version") != 1)
      return parse_error("unsupported GVM model version " + j.at("version").dump());
    MachineParams p;
    auto act = parse_activation(j.at("activation").get<std::string>());
    if (!act) return parse_error("unknown activation " + j.at("activation").dump());
    p.activation = *act;
    p.inputs = integer_at<size_t>(j, "inputs");
    p.outputs = integer_at<size_t>(j, "outputs");
    p.hidden = integer_at<size_t>(j, "hidden");
    j.at("input_names").get_to(p.input_names);
    j.at("output_names").get_to(p.output_names);
    j.at("in_min").get_to(p.in_min);
    j.at("in_max").get_to(p.in_max);
    j.at("out_min").get_to(p.out_min);
    j.at("out_max").get_to(p.out_max);
    j.at("out_a").get_to(p.out_a);
    j.at("out_c").get_to(p.out_c);
    p.w_max = j.at("w_max").get<double>();
    p.b_max = j.at("b_max").get<double>();
    p.beta_max = j.at("beta_max").get<double>();
    j.at("w").get_to(p.w);
    j.at("b").get_to(p.b);
    j.at("beta").get_to(p.beta);
    j.at("v").get_to(p.v);
    return p;
  } catch (const std::exception& e) {  // nlohmann's type errors and BadField
    return parse_error(std::string("GVM model JSON: ") + e.what());
  }
}

}  // namespace collido::gvm
