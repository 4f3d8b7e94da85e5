//! Who an OPC UA session is: gridscada's own users and roles. A username
//! token is checked by the same login check as the web's (throttling,
//! Argon2, a failed attempt on record); anonymous sessions exist only if the
//! configuration allows them, as the read-only guest. A user reads the tags
//! the HMI would show them (the screens of their group, docs/ACCESS.md, as of
//! the login); write rights (role and area) are looked up again at each
//! write, so a blocked or demoted user, or a group given fewer screens, loses
//! them without reconnecting.

use std::net::{IpAddr, Ipv6Addr};
use std::sync::atomic::Ordering;
use std::sync::Arc;

use async_trait::async_trait;
use gridscada_config::Role;
use gridscada_web::access::{default_screens, Readable};
use gridscada_web::auth::Principal;
use gridscada_web::command::{check_login, LoginRefused};
use gridscada_web::WebState;
use opcua::crypto::SecurityPolicy;
use opcua::server::address_space::AccessLevel;
use opcua::server::authenticator::{
    user_pass_security_policy_id, AuthManager, Password, UserToken,
};
use opcua::server::ServerEndpoint;
use opcua::types::{
    Error, Identifier, MessageSecurityMode, NodeId, StatusCode, UAString, UserTokenPolicy,
    UserTokenType,
};

use crate::Metrics;

/// The policy id of anonymous tokens (the library's own, not exported).
const POLICY_ID_ANONYMOUS: &str = "anonymous";

/// The address logins are throttled under: the OPC UA library does not hand
/// the peer's address to the credential check, so every OPC UA client shares
/// this one (the per-user limit still holds for each name).
const OPCUA_PEER: IpAddr = IpAddr::V6(Ipv6Addr::UNSPECIFIED);

/// A user's rights as of their login: role, group and the tags they read.
#[derive(Clone)]
struct LoginRights {
    role: Role,
    group: String,
    reads: Arc<Readable>,
}

pub(crate) struct Users {
    pub web: WebState,
    pub anonymous: bool,
    pub metrics: Arc<Metrics>,
    /// Each logged-in user's role at login, for the access level a browse
    /// shows (writes look the user up again).
    roles: parking_lot::Mutex<std::collections::HashMap<String, LoginRights>>,
    /// What anonymous sessions read: a guest's default screens.
    anonymous_reads: Arc<Readable>,
}

impl Users {
    pub fn new(web: WebState, anonymous: bool, metrics: Arc<Metrics>) -> Users {
        Users {
            web,
            anonymous,
            metrics,
            roles: Default::default(),
            anonymous_reads: Arc::new(Readable::default()),
        }
    }

    /// Once the screens are loaded: what anonymous sessions may read (the
    /// guest role's default screens).
    pub fn with_guest_reads(mut self) -> Users {
        let guest = Principal {
            user: Some("anonymous".into()),
            role: Role::Guest,
            group: None,
            screens: default_screens(&self.web.plant, &self.web.screens, Role::Guest),
        };
        self.anonymous_reads = Arc::new(self.web.readable(&guest));
        self
    }

    /// The caller behind a session's token, as the store describes them now;
    /// a Bad status when they may not act (blocked, deleted, store away).
    pub async fn principal(&self, token: &UserToken) -> Result<Principal, StatusCode> {
        if token.is_anonymous() {
            return Ok(Principal::anonymous());
        }
        match self.web.store.user(&token.0).await {
            // The screens as of now: a write's area is checked against them
            // (gridscada_web::command::write_tag), as the HMI's is.
            Ok(Some(u)) if !u.blocked => Ok(Principal {
                screens: self.web.screens_of(&u.group, u.role).await,
                user: Some(u.name),
                role: u.role,
                group: Some(u.group),
            }),
            Ok(_) => Err(StatusCode::BadUserAccessDenied),
            Err(e) => {
                tracing::warn!(error = %e, "OPC UA write: cannot look up the user");
                Err(StatusCode::BadResourceUnavailable)
            }
        }
    }
}

#[async_trait]
impl AuthManager for Users {
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        if self.anonymous {
            Ok(())
        } else {
            Err(Error::new(
                StatusCode::BadIdentityTokenRejected,
                "anonymous sessions are off ([opcua] anonymous): log in as a gridscada user",
            ))
        }
    }

    async fn authenticate_username_identity_token(
        &self,
        _endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let refused = |why: &str| {
            self.metrics.logins_refused.fetch_add(1, Ordering::Relaxed);
            Err(Error::new(StatusCode::BadUserAccessDenied, why.to_string()))
        };
        let user = match check_login(
            &self.web,
            username,
            password.get().to_string(),
            OPCUA_PEER,
            "opcua",
        )
        .await
        {
            Ok(u) => u,
            Err(LoginRefused::Invalid) => return refused("invalid username or password"),
            Err(LoginRefused::Throttled(wait)) => {
                return refused(&format!(
                    "too many failed logins; try again in {} s",
                    wait.as_secs().max(1)
                ))
            }
            Err(LoginRefused::Busy) => {
                return Err(Error::new(
                    StatusCode::BadResourceUnavailable,
                    "the server is busy checking other logins",
                ))
            }
            Err(LoginRefused::Store(e)) => {
                return Err(Error::new(
                    StatusCode::BadResourceUnavailable,
                    format!("cannot check the login now: {e}"),
                ))
            }
        };
        let who = Principal {
            user: Some(user.name.clone()),
            role: user.role,
            group: Some(user.group.clone()),
            screens: self.web.screens_of(&user.group, user.role).await,
        };
        // The tags the HMI would let this user read, as of this login.
        let reads = Arc::new(self.web.readable(&who));
        self.roles.lock().insert(
            user.name.clone(),
            LoginRights {
                role: user.role,
                group: user.group.clone(),
                reads,
            },
        );
        gridscada_web::api::audit(
            &self.web,
            &who,
            "login",
            "opcua",
            format!("{} logged in via OPC UA", user.name),
        )
        .await;
        Ok(UserToken(user.name))
    }

    fn effective_user_access_level(
        &self,
        token: &UserToken,
        level: AccessLevel,
        node_id: &NodeId,
    ) -> AccessLevel {
        // Only tag variables (and their units) are subject to the plant's
        // access rules; the server's own nodes keep their levels.
        let Identifier::String(id) = &node_id.identifier else {
            return level;
        };
        let id = id.as_ref();
        let tag = id.strip_suffix("#EngineeringUnits").unwrap_or(id);
        if self.web.db.id(tag).is_none() {
            return level;
        }
        let guest = |reads| LoginRights {
            role: Role::Guest,
            group: String::new(),
            reads,
        };
        let LoginRights { role, group, reads } = if token.is_anonymous() {
            guest(self.anonymous_reads.clone())
        } else {
            self.roles
                .lock()
                .get(&token.0)
                .cloned()
                .unwrap_or_else(|| guest(Arc::new(Readable::default())))
        };
        let mut level = level;
        if !reads.may_read(tag) {
            // As in the HMI: a tag outside the caller's screens is not read,
            // nor written unless the configuration grants their group it.
            level -= AccessLevel::CURRENT_READ;
            if !self.web.plant.server.grants_write(&group, tag) {
                level -= AccessLevel::CURRENT_WRITE;
            }
        }
        if tag == id
            && level.contains(AccessLevel::CURRENT_WRITE)
            && self.web.write_role(tag).is_none_or(|r| role < r)
        {
            level -= AccessLevel::CURRENT_WRITE;
        }
        level
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = Vec::with_capacity(2);
        if self.anonymous {
            policies.push(UserTokenPolicy {
                policy_id: UAString::from(POLICY_ID_ANONYMOUS),
                token_type: UserTokenType::Anonymous,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        // On an endpoint without security the password is still encrypted
        // with the server's key (the endpoint's password policy).
        let password_policy = endpoint.password_security_policy();
        let unsecured = endpoint.security_mode == MessageSecurityMode::None.to_string();
        policies.push(UserTokenPolicy {
            policy_id: user_pass_security_policy_id(endpoint),
            token_type: UserTokenType::UserName,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: if unsecured && password_policy != SecurityPolicy::None {
                UAString::from(password_policy.to_uri())
            } else {
                UAString::null()
            },
        });
        policies
    }
}
