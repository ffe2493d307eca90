"""The curriculum: marginal value V̄, adaptive MCMC sampling ([WL19] §4.2), elites, density and
phases ([L21] §5-6). Import the modules themselves: only those that hold networks
(`marginal_value`, `parameterization_net`) load torch."""
